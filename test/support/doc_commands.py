"""The shell commands in a Markdown file's ```bash blocks, as argv lists (continuations joined, comments dropped,
`&&` / `;` / `|` split into separate commands), each with the line it starts on."""
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

SEPARATORS = {"&&", ";", "||", "|"}
# `$(ros2 pkg prefix --share PKG)` -> one token, SHARE_TOKEN.format(PKG): a checker resolves it to that share folder
SHARE_SUBSTITUTION = re.compile(r"\$\(ros2 pkg prefix --share ([A-Za-z0-9_]+)\)")
SHARE_TOKEN = "@share:{}@"


@dataclass(frozen=True)
class DocCommand:
    line: int
    argv: tuple

    def __str__(self) -> str:
        return f"line {self.line}: {shlex.join(self.argv)}"


def bash_blocks(path: Path, section: str | None = None):
    """(first line number, text) of every ```bash block (only under the heading `section`, if given)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    start, inside = None, section is None
    for number, line in enumerate(lines, 1):
        if section is not None and start is None and re.match(r"^#{1,6} ", line):
            inside = line.lstrip("#").strip() == section
        if not inside:
            continue
        if start is None and re.match(r"^\s*```bash\s*$", line):
            start, body = number + 1, []
        elif start is not None and re.match(r"^\s*```\s*$", line):
            yield start, "\n".join(body)
            start = None
        elif start is not None:
            body.append(line)


def _split(tokens):
    command = []
    for token in tokens:
        if token in SEPARATORS:
            if command:
                yield command
            command = []
        else:
            command.append(token)
    if command:
        yield command


def commands(path: Path, section: str | None = None) -> list[DocCommand]:
    out = []
    for first, text in bash_blocks(path, section):
        logical, begin = "", None
        for offset, raw in enumerate(text.splitlines()):
            if begin is None:
                begin = first + offset
            stripped = raw.rstrip()
            if stripped.endswith("\\") and not stripped.lstrip().startswith("#"):
                logical += stripped[:-1] + " "
                continue
            logical += raw
            logical = SHARE_SUBSTITUTION.sub(lambda m: SHARE_TOKEN.format(m.group(1)), logical)
            lexer = shlex.shlex(logical, posix=True, punctuation_chars=";&|")
            lexer.whitespace_split, lexer.commenters = True, "#"
            out += [DocCommand(begin, tuple(argv)) for argv in _split(list(lexer))]
            logical, begin = "", None
    return out


def option_value(argv, name: str) -> str | None:
    """`--name=value` or `--name value` in argv, else None."""
    for index, token in enumerate(argv):
        if token.startswith(name + "="):
            return token.split("=", 1)[1]
        if token == name and index + 1 < len(argv):
            return argv[index + 1]
    return None
