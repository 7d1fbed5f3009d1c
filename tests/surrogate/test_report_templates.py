"""The report templates (liverviz.report.render, bench/templates): a name the driver did not
give raises instead of printing nothing, numbers are formatted as asked ("n/a" for a missing
one), a paragraph written over lines is one markdown line, and every template parses."""

import math
from pathlib import Path

import jinja2
import pytest

from liverviz.report import ROOT, render
from surrogate.reports import REPORT_NAMES


def test_render_formats_joins_and_refuses_unknown_names(tmp_path):
    t = tmp_path / "t.md.j2"
    t.write_text('{% filter oneline %}\n- MEE {{ x|f(".3f") }} mm,\n  skill {{ y|f(".2f") }}.\n'
                 '{% endfilter %}\n\n{{ row(a, "", b|f(",")) }}\n{{ mean([1, 2, 4])|f(".4f") }}\n')
    text = render(t, x=0.12345, y=math.nan, a="k", b=12345, **REPORT_NAMES)
    assert text == "- MEE 0.123 mm, skill n/a.\n| k |  | 12,345 |\n2.3333\n"
    with pytest.raises(jinja2.UndefinedError, match="'b' is undefined"):
        render(t, x=1.0, y=2.0, a="k")


@pytest.mark.parametrize("template", sorted((ROOT / "bench" / "templates").glob("*.j2")),
                         ids=lambda p: p.name)
def test_every_report_template_parses(template: Path):
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(template.parent))
    env.parse(template.read_text())
