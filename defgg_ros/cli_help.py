"""The help formatter of every defgg-* command: descriptions kept as written, and each option's default
shown where it says something (not None, False or empty) and the help text does not already name it."""
import argparse


def _says_something(default) -> bool:
    if default is None or default is False or default is argparse.SUPPRESS:
        return False
    return not (isinstance(default, (str, list, tuple)) and len(default) == 0)


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    def _get_help_string(self, action):
        text = action.help or ""
        if action.option_strings and _says_something(action.default) and "default" not in text.lower():
            return f"{text} (default: %(default)s)"
        return text


def use_for(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Give `parser` and its subcommands' parsers this formatter (add_parser does not inherit it)."""
    parser.formatter_class = HelpFormatter
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                use_for(sub)
    return parser
