"""launch.substitutions: each has perform(context) -> str, as the real ones do."""
import os


def perform_all(value, context) -> str:
    """A SomeSubstitutionsType (str, substitution, or a list of them, concatenated) -> str."""
    if isinstance(value, str):
        return value
    if isinstance(value, (list, tuple)):
        return "".join(perform_all(item, context) for item in value)
    return value.perform(context)


class LaunchConfiguration:
    def __init__(self, variable_name, *, default=None):
        self.variable_name = variable_name
        self.default = default

    def perform(self, context) -> str:
        if self.variable_name in context.launch_configurations:
            return context.launch_configurations[self.variable_name]
        if self.default is None:
            raise KeyError(f"launch configuration {self.variable_name!r} does not exist")
        return perform_all(self.default, context)


class PathJoinSubstitution:
    def __init__(self, substitutions):
        self.substitutions = list(substitutions)

    def perform(self, context) -> str:
        return os.path.join(*(perform_all(part, context) for part in self.substitutions))
