"""A report section that another benchmark owns survives the report's own rewrite, and is
replaced, not repeated, when its owner writes it again (liverviz/report.py)."""

from liverviz.report import put_section, sections


def test_a_section_is_appended_then_replaced_and_kept(tmp_path):
    md = tmp_path / "r.md"
    md.write_text("# report\n\nrealtime: scene 1 line\n")
    put_section(md, "table4", "realtime: scene 4, a 1.00 ms")
    put_section(md, "table4", "realtime: scene 4, b 2.00 ms")
    text = md.read_text()
    assert text.startswith("# report\n\nrealtime: scene 1 line\n\n<!-- begin table4 -->\n")
    assert "b 2.00 ms" in text and "a 1.00 ms" not in text
    assert text.count("<!-- begin table4 -->") == 1
    # the report's own benchmark rewrites the rest and keeps the section
    kept = sections(md)
    md.write_text("# report, regenerated\n\n" + kept)
    assert "realtime: scene 4, b 2.00 ms" in md.read_text()
    put_section(md, "other", "x")
    assert sections(md).count("<!-- end ") == 2
    assert sections(tmp_path / "missing.md") == ""


def test_write_report_keeps_the_measured_and_rejected_section(tmp_path):
    """What was measured by hand and not kept lives in its report, not in the driver: the
    driver's rewrite keeps it after the new body."""
    from liverviz.report import write_report

    md = tmp_path / "r.md"
    write_report(md, "R", "body one", {"x": 1})
    put_section(md, "measured-and-rejected", "HXT: not reproducible, not kept.")
    write_report(md, "R", "body two", {"x": 2})
    text = md.read_text()
    assert "body one" not in text and "body two" in text
    assert text.index("body two") < text.index("<!-- begin measured-and-rejected -->")
    assert text.count("HXT: not reproducible") == 1
