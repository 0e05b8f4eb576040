"""launch.actions: the actions the cell's launch files use."""


class DeclareLaunchArgument:
    def __init__(self, name, *, default_value=None, description=None, choices=None):
        self.name = name
        self.default_value = default_value
        self.description = description
        self.choices = list(choices) if choices is not None else None


class SetEnvironmentVariable:
    def __init__(self, name, value):
        self.name = name
        self.value = value
