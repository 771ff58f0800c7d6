"""What the generators write: a block in a hand-written doc (only the part between its markers
changes) and figures (atomically, closed after)."""

from __future__ import annotations

import pytest

from addedinertia_env.reports.sections import replace_section

BEGIN, END = "<!-- t:begin -->", "<!-- t:end -->"


def test_the_block_between_the_markers_is_replaced_and_the_rest_kept(tmp_path):
    doc = tmp_path / "DOC.md"
    doc.write_text(f"# Title\n\nhand text\n\n{BEGIN}\nold table\n{END}\n\nafter\n")
    replace_section(doc, f"{BEGIN}\nnew table\n{END}", BEGIN, END)
    assert doc.read_text() == f"# Title\n\nhand text\n\n{BEGIN}\nnew table\n{END}\n\nafter\n"
    assert [p.name for p in tmp_path.iterdir()] == ["DOC.md"]  # no temporary file left


def test_a_doc_without_the_markers_gets_the_block_appended_under_its_heading(tmp_path):
    doc = tmp_path / "DOC.md"
    doc.write_text("# Title\n\nhand text\n")
    replace_section(doc, f"{BEGIN}\nrows\n{END}\n", BEGIN, END, heading="## Generated")
    assert doc.read_text() == f"# Title\n\nhand text\n\n## Generated\n\n{BEGIN}\nrows\n{END}\n"
    replace_section(tmp_path / "NEW.md", f"{BEGIN}\nx\n{END}", BEGIN, END)
    assert (tmp_path / "NEW.md").read_text() == f"{BEGIN}\nx\n{END}\n"


def test_a_block_without_its_own_markers_is_refused(tmp_path):
    with pytest.raises(ValueError, match="must start with"):
        replace_section(tmp_path / "DOC.md", "a table with no markers", BEGIN, END)


def test_a_figure_is_written_atomically_and_closed(tmp_path):
    """atomic.save_figure: the PNG appears whole under its name (its folder made), no temporary
    file stays, and pyplot no longer holds the figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from addedinertia_env.foundation.atomic import save_figure

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    path = save_figure(fig, tmp_path / "figs" / "line.png", dpi=50)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in path.parent.iterdir()] == ["line.png"]
    assert fig.number not in plt.get_fignums()
