"""Models of the tests made by editing a model file's text (no OpenSim): one setting changed."""

from __future__ import annotations

from pathlib import Path


def with_locked_coordinate(model: Path, coordinate: str, out: Path) -> Path:
    """``model`` with ``<locked>true</locked>`` on ``coordinate`` (nothing else changed), written to ``out``."""
    text = Path(model).read_text()
    start = text.index(f'<Coordinate name="{coordinate}">')
    end = text.index("</Coordinate>", start)
    block = text[start:end]
    assert block.count("<locked>false</locked>") == 1, f"{coordinate} is not an unlocked coordinate of {model}"
    out.write_text(text[:start] + block.replace("<locked>false</locked>", "<locked>true</locked>") + text[end:])
    return out
