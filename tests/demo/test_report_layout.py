"""The report's summary table fits the page: a fixed layout whose column widths add up to the table's width, and
long cells (refinement names, the reason a run was not repaired) wrap instead of widening it."""

from __future__ import annotations

import re
from html.parser import HTMLParser

from bt_meta.demo import report

LONG_REASON = ("collision at step 5: reported with its evidence, not repaired (no plugin proposed a different motion) "
               + "x" * 300)


def _run(**changes: object) -> dict[str, object]:
    run: dict[str, object] = {
        "pass": 1, "family": "housing", "problem": "nominal", "variant": "housing_upside_down", "status": "failed",
        "attempts": 1, "failure_kinds": ["collision"], "repairs": [], "refinements_used": [],
        "refinement_saved": "refined_AttachAndVerify_e1837f2e_with_a_very_long_name_that_has_no_spaces_at_all",
        "stop_reason": LONG_REASON, "error": None, "achieved": False, "truth": "the housing is not inserted",
        "ticks": 39, "seconds": 0.97,
    }
    run.update(changes)
    return run


class _Table(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.table_class = ""
        self.col_widths: list[float] = []
        self.headers = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        values = dict(attrs)
        if tag == "table":
            self.table_class = values.get("class") or ""
        elif tag == "col":
            match = re.fullmatch(r"width:([0-9.]+)%", values.get("style") or "")
            assert match, values
            self.col_widths.append(float(match.group(1)))
        elif tag == "th":
            self.headers += 1


def _css_rules() -> dict[str, str]:
    css = re.sub(r"\s+", "", report._CSS)
    return {selector: body for selector, body in re.findall(r"([^{}]+)\{([^}]*)\}", css)}


def test_summary_table_has_a_fixed_layout_that_adds_up_to_the_page():
    html = report._summary_table({"runs": [_run(), _run(**{"pass": 2, "status": "success", "stop_reason": None})]})
    table = _Table()
    table.feed(html)
    assert "fit" in table.table_class.split()
    assert len(table.col_widths) == table.headers == 13
    assert sum(table.col_widths) == 100.0
    assert LONG_REASON in html  # wrapped, not cut


def test_the_stylesheet_wraps_long_cells_inside_fixed_tables():
    rules = _css_rules()
    assert "table-layout:fixed" in rules["table.fit"] and "width:100%" in rules["table.fit"]
    assert "overflow-wrap:anywhere" in rules["td"]  # a 300-character token breaks inside its column
    assert "max-width:100%" in rules["table"]  # the other tables do not push past the page either
    assert "white-space:nowrap" in rules[".pill"]  # status pills stay whole in narrow columns
