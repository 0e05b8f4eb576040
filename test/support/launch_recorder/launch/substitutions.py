"""launch.substitutions: each has perform(context) -> str, as the real ones do."""
import os


def _one(item, context) -> str:
    # launch's normalize_to_list_of_substitutions: each item is a str or a Substitution, nothing else (Jazzy)
    if isinstance(item, str):
        return item
    if hasattr(item, "perform"):
        return item.perform(context)
    raise TypeError(f"Failed to normalize given item of type '{type(item)}', when only 'str' or "
                    "'launch.Substitution' were expected.")


def perform_all(value, context) -> str:
    """A SomeSubstitutionsType (a str, a substitution, or a flat list of them, concatenated) -> str."""
    if isinstance(value, (list, tuple)):
        return "".join(_one(item, context) for item in value)
    return _one(value, context)


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
        return os.path.join(*(_one(part, context) for part in self.substitutions))
