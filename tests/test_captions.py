"""Captions from Bandai Namco labels: coverage of every real label, grammar, left/right, mirroring."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from kinema.data.captions import (
    CONTENT_PHRASES,
    STYLE_PHRASES,
    captions_for,
    load_labels,
    mirror_content,
)
from kinema.data.split import parse_clip_name
from kinema.errors import DataError


def _dataset_dir(root: Path, number: int) -> Path:
    """A dataset folder of the Bandai data in use (real, or synthetic with the real label files: conftest.py)."""
    return root / f"Bandai-Namco-Research-Motiondataset-{number}"


SUBJECT = re.compile(r"^(A|An|Someone)\b")
WORD = re.compile(r"[A-Za-z'-]+")


def _side_words(text: str) -> set[str]:
    return {w for w in re.findall(r"\b(left|right)\b", text.lower())}


def _check_caption(text: str) -> None:
    assert SUBJECT.match(text), text
    assert text[0].isupper() and text.endswith("."), text
    assert text.count(".") == 1, text
    assert "  " not in text and text == text.strip(), text
    assert not re.search(r"[{}<>\[\]]", text), text  # no unfilled template markers
    assert not re.search(r"\bA [aeiouAEIOU]", text), text
    assert not re.search(r"\bAn [^aeiouAEIOU]", text), text
    assert " ," not in text and ",," not in text, text
    if text.startswith("A man "):
        assert not re.search(r"\b(their|her)\b", text), text
    if text.startswith(("A woman ", "A graceful woman ")):
        assert not re.search(r"\b(their|his)\b", text), text


def _check_clip(content: str, style: str) -> None:
    for mirrored in (False, True):
        caps = captions_for(content, style, mirrored=mirrored)
        assert len(caps) >= 3, (content, style)
        assert len(set(caps)) == len(caps), caps
        for text in caps:
            _check_caption(text)
            if re.match(r"^(A man|A woman)\b", text):
                assert style in {"masculinity", "masculine", "feminine"}, text
        assert caps == captions_for(content, style, mirrored=mirrored)  # deterministic
    swap = {"left": "right", "right": "left"}
    side = {"left", "right"} & set(content.split("-"))
    for text, mirrored_text in zip(captions_for(content, style), captions_for(content, style, True), strict=True):
        assert _side_words(mirrored_text) == {swap[w] for w in _side_words(text)}, mirrored_text
        if side:  # the label names a side: every caption says exactly that side
            assert _side_words(text) == side, text


@pytest.mark.parametrize("number", [1, 2], ids=lambda n: f"dataset-{n}")
def test_every_real_label_pair_has_good_captions(bandai_root: Path, number: int) -> None:
    contents, styles = load_labels(_dataset_dir(bandai_root, number))
    assert all(not c.startswith("dataset-") and "_" not in c for c in contents + styles)
    for content in contents:
        assert mirror_content(mirror_content(content)) == content
        for style in styles:
            _check_clip(content, style)


def test_real_label_files_match_readmes(bandai_root: Path) -> None:
    c1, s1 = load_labels(_dataset_dir(bandai_root, 1))
    c2, s2 = load_labels(_dataset_dir(bandai_root, 2))
    assert len(c1) == 17 and len(s1) == 15 and c1[3:6] == ["walk-back", "walk-left", "walk-right"]
    assert len(c2) == 10 and len(s2) == 7 and c2[-1] == "raise-up-right-hand" and s2[-1] == "youthful"


@pytest.mark.parametrize("number", [1, 2], ids=lambda n: f"dataset-{n}")
def test_json_twins_agree_with_file_names(bandai_root: Path, number: int) -> None:
    dataset_dir = _dataset_dir(bandai_root, number)
    contents, styles = load_labels(dataset_dir)
    twins = sorted((dataset_dir / "data").glob("*.json"))
    assert twins
    for path in twins[:: max(1, len(twins) // 60)]:
        meta = json.loads(path.read_text())
        fields = parse_clip_name(path.name)
        assert contents[meta["content"]] == fields["content"], path.name
        assert styles[meta["style"]] == fields["style"], path.name
        assert captions_for(fields["content"], fields["style"])


def test_side_specific_examples() -> None:
    for text in captions_for("wave-left-hand", "normal"):
        assert "left" in text and "right" not in text
    for text in captions_for("wave-left-hand", "normal", mirrored=True):
        assert "right" in text and "left" not in text
    assert captions_for("walk-turn-left", "exhausted", mirrored=True) == captions_for("walk-turn-right", "exhausted")
    # bye is done with the right hand, so its mirror is a left-handed wave
    assert all("right hand" in t for t in captions_for("bye", "happy"))
    assert all("left hand" in t for t in captions_for("bye", "happy", mirrored=True))
    assert "A person walks backwards proudly." in captions_for("walk-back", "proud")
    assert any("left" in t for t in captions_for("respond", "normal"))


def test_mirrored_equals_mirrored_content_for_sided_labels() -> None:
    styles = list(STYLE_PHRASES)
    for content in CONTENT_PHRASES:
        if mirror_content(content) != content:
            for style in styles:
                assert captions_for(content, style, mirrored=True) == captions_for(mirror_content(content), style)


def test_all_known_pairs_are_well_formed_without_data() -> None:
    for content in CONTENT_PHRASES:
        for style in STYLE_PHRASES:
            _check_clip(content, style)
    for words in STYLE_PHRASES.values():  # style text never names a side
        for phrase in words.subjects + words.manners + words.clauses:
            assert not _side_words(phrase), phrase


def test_mirror_content() -> None:
    pairs = {
        "walk-left": "walk-right",
        "wave-left-hand": "wave-right-hand",
        "walk-turn-left": "walk-turn-right",
        "raise-up-left-hand": "raise-up-right-hand",
    }
    for a, b in pairs.items():
        assert mirror_content(a) == b and mirror_content(b) == a
    for same in ("walk", "wave-both-hands", "bye", "bright-light"):
        assert mirror_content(same) == same
    for content in CONTENT_PHRASES:
        assert mirror_content(mirror_content(content)) == content


def test_unknown_labels_raise_with_the_label() -> None:
    with pytest.raises(DataError, match="moonwalk"):
        captions_for("moonwalk", "normal")
    with pytest.raises(DataError, match="sleepy"):
        captions_for("walk", "sleepy")


def test_load_labels_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="content_label.txt"):
        load_labels(tmp_path)
    cfg = tmp_path / "cfg"
    cfg.mkdir()
    (cfg / "content_label.txt").write_text("dataset-3_walk\ndataset-3_hop-left")  # no final newline
    (cfg / "style_label.txt").write_text("\n")
    with pytest.raises(DataError, match="style_label.txt"):
        load_labels(tmp_path)
    (cfg / "style_label.txt").write_text("dataset-3_calm\nnot prefixed\n")
    with pytest.raises(DataError, match=r"style_label.txt:2"):
        load_labels(tmp_path)
    (cfg / "style_label.txt").write_text("dataset-3_calm\ndataset-3_calm\n")
    with pytest.raises(DataError, match="repeated"):
        load_labels(tmp_path)
    (cfg / "style_label.txt").write_text("dataset-3_calm\n")
    assert load_labels(tmp_path) == (["walk", "hop-left"], ["calm"])
