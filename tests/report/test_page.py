"""The page and the job summary from report entries: a green page is short and says so, a
summary of very many goldens stays under GitHub's 1 MiB a step and counts what it leaves out,
and text from a golden (its path, what changed) is escaped, never markup."""

from __future__ import annotations

from twin.report.page import SUMMARY_LIMIT_BYTES, Entry, render_page, render_summary


def test_a_summary_of_many_goldens_stays_under_1_mib():
    entries = [Entry(f"recordings/g{i:05d}.mcap", "differ", "x" * 300, "step 1 (t = 0.004 s)")
               for i in range(10_000)]
    text = render_summary(entries, "twin check")
    assert len(text.encode()) <= SUMMARY_LIMIT_BYTES
    assert text.startswith("## twin check: 10000 differ\n")
    shown = text.count("| differ | **FAIL** |")
    assert 1000 < shown < 10_000
    assert f"| ... and {10_000 - shown} more | | | | |" in text


def test_a_green_page_is_short_and_says_every_golden_matched():
    entries = [Entry(f"recordings/g{i}.mcap", "match", "bit-identical") for i in range(13)]
    page = render_page(entries, "twin check", "Intel Xeon (fma avx2)")
    assert "twin check: every golden matched (13 of 13)" in page
    assert "<script" not in page and len(page) < 8_000
    assert page.count("<li id=") == 13 and "checked on: Intel Xeon (fma avx2)" in page


def test_text_from_a_golden_is_escaped():
    entry = Entry("a|<b>.mcap", "differ", "q <script>alert(1)</script> | x", "step 2")
    page = render_page([entry], "twin check")
    assert "<script>alert" not in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    summary = render_summary([entry], "twin check")
    assert "`a\\|<b>.mcap`" in summary  # a code span: taken literally
    assert "q &lt;script>alert(1)&lt;/script> \\| x" in summary
