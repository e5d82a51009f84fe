"""Files in UTF-16 (with either byte-order mark, or none), UTF-32 and UTF-8 with a mark read exactly like their UTF-8
originals in every format (APT, NX CLSF, G-code, CSV, JSON), through ``read_toolpath``, ``detect_format`` and ``plan``;
binary data and UTF-16 decoded with the wrong codec are refused naming the line and the cause."""

from __future__ import annotations

import codecs
import io

import numpy as np
import pytest

from planner import PlanSettings, plan
from planner.io import InputFileError, detect_format, read_apt, read_csv, read_json, read_toolpath
from tests.cam_excerpts import EXCERPTS

#: name -> the text of a file of each format (the real CAM ones are the first lines of the verbatim excerpts).
TEXTS = {
    "boss.apt": EXCERPTS["solidworks_cam_apt_boss_excerpt.apt"].head(53),
    "ust_a2.cls": EXCERPTS["nx_clsf_ust_a2_excerpt.cls"].head(100),
    "haas.nc": EXCERPTS["nx2022_haas_umc750_excerpt.txt"].head(76).lstrip("\ufeff"),
    "points.csv": "x,y,z,i,j,k\n0,0,0,0,0,1\n10,0,1,0,0.6,0.8\n20,5,2,0,0,1\n",
    "points.json": '{"units": "mm", "points": [[0, 0, 0], [10, 0, 1], [20, 5, 2], [30, 5, 0]]}\n',
}

#: encoding name -> the bytes of a text in it, as editors and CAM systems on Windows write them.
ENCODINGS = {
    "utf-8-bom": lambda t: codecs.BOM_UTF8 + t.encode("utf-8"),
    "utf-16-le-bom": lambda t: codecs.BOM_UTF16_LE + t.encode("utf-16-le"),
    "utf-16-be-bom": lambda t: codecs.BOM_UTF16_BE + t.encode("utf-16-be"),
    "utf-16-le": lambda t: t.encode("utf-16-le"),
    "utf-16-be": lambda t: t.encode("utf-16-be"),
    "utf-32-le-bom": lambda t: codecs.BOM_UTF32_LE + t.encode("utf-32-le"),
    "utf-16-le-bom-crlf": lambda t: codecs.BOM_UTF16_LE + t.replace("\n", "\r\n").encode("utf-16-le"),
}


def same(a, b) -> None:
    """Two toolpaths alike in every array and event (the source names may differ)."""
    assert len(a) == len(b) and a.units == b.units
    for name in ("points", "feeds", "rapid", "lines", "axes", "axis_given", "rotary"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert np.array_equal(x, y, equal_nan=True), name
    assert [(e.kind, e.line, e.index) for e in a.events] == [(e.kind, e.line, e.index) for e in b.events]


@pytest.mark.parametrize("encoding", list(ENCODINGS))
@pytest.mark.parametrize("name", list(TEXTS))
def test_every_format_reads_alike_in_every_encoding(name, encoding, tmp_path):
    plain = tmp_path / name
    plain.write_bytes(TEXTS[name].encode("utf-8"))
    other = tmp_path / ("enc_" + name)
    other.write_bytes(ENCODINGS[encoding](TEXTS[name]))
    assert other.read_bytes() != plain.read_bytes()
    ref = read_toolpath(plain)
    assert len(ref) >= 3
    same(read_toolpath(other), ref)
    # the content sniffer sees through the encoding too (a .txt name tells nothing)
    sniffed = tmp_path / (name + ".txt")
    sniffed.write_bytes(other.read_bytes())
    assert detect_format(sniffed) == detect_format(plain)


def test_plan_of_a_utf16_apt_file_is_the_plan_of_its_utf8_original(tmp_path):
    text = TEXTS["boss.apt"]
    (tmp_path / "a.apt").write_bytes(text.encode("utf-8"))
    (tmp_path / "b.apt").write_bytes(codecs.BOM_UTF16_LE + text.encode("utf-16-le"))
    a, b = (plan(tmp_path / n, PlanSettings(path="cam")) for n in ("a.apt", "b.apt"))
    assert (len(a.moves), a.count("cut")) == (len(b.moves), b.count("cut")) and a.count("cut") > 5
    sa, sb = a.summary(), b.summary()
    for key in ("points", "passes", "rapids", "cut_length_mm", "duration_s", "max_deviation_mm", "spin_deg"):
        assert sa[key] == sb[key], key


@pytest.mark.parametrize(
    "data, line, words",
    [
        (b"GOTO/1,2,3\nGOTO/4,5,6\n\x89PNG\x00\x00\x00\rIHDR", 3, ["NUL byte", "binary data", "UTF-16"]),
        (b"\x00\x01\x02\x03\x04\x05GOTO/1,2,3\n", 1, ["NUL byte (byte 0", "not a toolpath file"]),
    ],
)
def test_binary_data_is_refused_naming_the_line(data, line, words, tmp_path):
    path = tmp_path / "x.apt"
    path.write_bytes(data)
    with pytest.raises(InputFileError) as exc:
        read_toolpath(path)
    assert exc.value.line == line and str(exc.value).startswith(f"x.apt line {line}: ")
    for w in words:
        assert w in str(exc.value)


@pytest.mark.parametrize("reader, text", [(read_apt, TEXTS["boss.apt"]), (read_csv, TEXTS["points.csv"]),
                                          (read_json, TEXTS["points.json"])])
@pytest.mark.parametrize("wrong", ["latin-1", "utf-8"])
def test_utf16_decoded_with_the_wrong_codec_is_refused_naming_the_encoding(reader, text, wrong):
    data = codecs.BOM_UTF16_LE + text.encode("utf-16-le")
    with pytest.raises(InputFileError) as exc:
        reader(io.StringIO(data.decode(wrong, errors="replace")), source="s")
    assert exc.value.line == 1 and "UTF-16" in str(exc.value) and "encoding='utf-16'" in str(exc.value)
    # the same stream decoded rightly reads like the text (a UTF-8 mark decoded as Latin-1 is dropped too)
    right = reader(io.StringIO(data.decode("utf-16")), source="s")
    same(right, reader(io.StringIO(text), source="s"))
    same(reader(io.StringIO((codecs.BOM_UTF8 + text.encode()).decode("latin-1")), source="s"), right)
