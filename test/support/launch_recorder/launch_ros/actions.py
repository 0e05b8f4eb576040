"""launch_ros.actions.Node: what it would run, kept for the recorder."""


class Node:
    def __init__(self, *, executable, package=None, name=None, namespace=None, exec_name=None, parameters=None,
                 remappings=None, ros_arguments=None, arguments=None, output="log", **kwargs):
        unknown = set(kwargs) - {"respawn", "respawn_delay", "emulate_tty", "sigterm_timeout", "sigkill_timeout",
                                 "additional_env", "condition"}
        if unknown:
            raise TypeError(f"Node() got arguments launch_ros.actions.Node has not: {sorted(unknown)}")
        self.package = package
        self.executable = executable
        self.name = name
        self.namespace = namespace
        self.parameters = list(parameters or [])
        self.remappings = list(remappings or [])
        self.arguments = list(arguments or [])
        self.output = output
