"""The replay's per-frame diff table and its verdict. No rclpy."""
from dataclasses import dataclass, field

from defgg_ros.sessions.compare import GraspSummary, grasp_diff


@dataclass
class Row:
    item: str                 # "frame 3", "plan 0", "pick 0"
    expected: str
    actual: str
    diff: str = ""
    problems: list = field(default_factory=list)

    @property
    def status(self) -> str:
        return "REGRESSION" if self.problems else "ok"


def diff_text(expected: GraspSummary | None, actual: GraspSummary | None) -> str:
    if expected is None or actual is None:
        return "-"
    d = grasp_diff(expected, actual)
    return f"d={d.position_mm:.1f}mm {d.angle_deg:.1f}deg {d.width_mm:.1f}mm"


def format_table(title: str, rows: list[Row]) -> str:
    headers = ("item", "recorded", "replayed", "difference", "status")
    cells = [(r.item, r.expected, r.actual, r.diff, r.status) for r in rows]
    widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h) for i, h in enumerate(headers)]
    line = "  ".join(h.ljust(w) for h, w in zip(headers, widths))
    out = [title, line, "-" * len(line)]
    out += ["  ".join(c.ljust(w) for c, w in zip(cell, widths)) for cell in cells]
    return "\n".join(out)


def regression_message(session_name: str, rows: list[Row], cause: str = "",
                       session_path: str = "") -> str | None:
    """None when everything matched, else one line per changed item saying what changed.

    `cause`: a known difference from the recording (e.g. another model) to name first. `session_path`: the
    path the update command needs (default: the name).
    """
    bad = [r for r in rows if r.problems]
    if not bad:
        return None
    lines = [f"REGRESSION in session {session_name}: {len(bad)} of {len(rows)} item(s) changed"
             + (f" ({cause})" if cause else "")]
    lines += [f"  {r.item}: " + "; ".join(r.problems) for r in bad]
    lines.append("  (if the change is intended, re-record the expectations with: defgg-replay --update "
                 f"{session_path or session_name})")
    return "\n".join(lines)
