"""Tests of gpf.rtl.gtkw: the text of the GTKWave save files it renders."""

from __future__ import annotations

import gzip
import re
import struct
from pathlib import Path

import pytest

from gpf.rtl import gtkw
from gpf.rtl.gtkw import Group, Trace, render_gtkw, write_gtkw

DOT = gtkw.LABEL_DOT


def body(text: str) -> list[str]:
    """The lines after the header comments and the [dumpfile] line."""
    lines = text.splitlines()
    return lines[[i for i, line in enumerate(lines) if line.startswith("[dumpfile]")][0] + 1 :]


def flags_of(text: str, trace_line: str) -> int:
    """The flags in force (last '@' line) where ``trace_line`` appears."""
    flags = None
    for line in body(text):
        if line.startswith("@"):
            flags = int(line[1:], 16)
        if line == trace_line:
            assert flags is not None
            return flags
    raise AssertionError(f"{trace_line!r} not in the save file")


def fpshift_of(text: str, trace_line: str) -> int | None:
    """The [fpshift_count] written just before ``trace_line``, if any."""
    lines = body(text)
    i = lines.index(trace_line)
    match = re.fullmatch(r"\[fpshift_count\] (\d+)", lines[i - 1])
    return int(match[1]) if match else None


def bits(parent: str, ks) -> str:
    return " ".join(f"({k}){parent}" for k in ks)


MISSING = Path("/nonexistent/dump.fst")  # no dump: traces are taken as whole signals

GROUPS = [
    Group(
        "grng",
        [
            Trace("tb.grng.clk", 0, 0),
            Trace("tb.grng.m_axis_tdata", 15, 0, label="lane0.z", signed=True, frac_bits=14),
            Trace("tb.grng.m_axis_tdata", 15, 0, label="lane0.raw"),
        ],
    ),
    Group(
        "state",
        [
            Trace("tb.pf.weight", 17, 0, frac_bits=16),
            Trace("tb.pf.count", 9, 0, signed=True, frac_bits=0),
            Trace("tb.pf.count", 9, 0, frac_bits=0, label="count"),
        ],
    ),
    Group("empty", []),
]


# --- flag values ---------------------------------------------------------------------------------


def test_flag_values_match_gtkwave_analyzer_h():
    # Bit positions of enum TraceEntFlagBits in GTKWave's src/analyzer.h.
    assert gtkw.TR_HEX == 0x2
    assert gtkw.TR_DEC == 0x4
    assert gtkw.TR_RJUSTIFY == 0x20
    assert gtkw.TR_BLANK == 0x200
    assert gtkw.TR_SIGNED == 0x400
    assert gtkw.TR_CLOSED == 0x400000
    assert gtkw.TR_GRP_BEGIN == 0x800000
    assert gtkw.TR_GRP_END == 0x1000000
    assert gtkw.TR_FPDECSHIFT == 0x40000000
    # The combinations GTKWave itself writes for these formats.
    assert gtkw.FLAGS_HEX == 0x22
    assert gtkw.FLAGS_SFIX == 0x40000420
    assert gtkw.FLAGS_UFIX == 0x40000024
    assert gtkw.FLAGS_GROUP_BEGIN == 0x800200
    assert gtkw.FLAGS_GROUP_END == 0x1000200


# --- layout --------------------------------------------------------------------------------------


def test_header_and_dumpfile():
    text = render_gtkw(Path("build/sim/dump.fst"), GROUPS)
    assert text.endswith("\n")
    assert '[dumpfile] "build/sim/dump.fst"' in text.splitlines()
    assert all(line.startswith("[*]") for line in text.splitlines()[:3])


def test_groups_balanced_and_named():
    text = render_gtkw(MISSING, GROUPS)
    lines = body(text)
    stack: list[str] = []
    opened: list[str] = []
    flags = None
    for i, line in enumerate(lines):
        if line.startswith("@"):
            flags = int(line[1:], 16)
        elif line.startswith("-"):
            assert flags is not None and flags & gtkw.TR_BLANK
            assert lines[i - 1].startswith("@"), "each group marker gets its own flags line"
            if flags & gtkw.TR_GRP_BEGIN:
                stack.append(line[1:])
                opened.append(line[1:])
            else:
                assert flags & gtkw.TR_GRP_END
                assert stack.pop() == line[1:]
        else:
            assert stack, f"{line!r} outside any group"
    assert stack == []
    assert opened == ["grng", "state", "empty"]
    assert lines.count("@800200") == 3
    assert lines.count("@1000200") == 3


def test_trace_lines_flags_and_shift():
    text = render_gtkw(MISSING, GROUPS)
    lane_z = f"+{{lane0{DOT}z}} tb.grng.m_axis_tdata[15:0]"
    lane_raw = f"+{{lane0{DOT}raw}} tb.grng.m_axis_tdata[15:0]"

    assert flags_of(text, "tb.grng.clk") == 0x22
    assert fpshift_of(text, "tb.grng.clk") is None

    assert flags_of(text, lane_z) == 0x40000420  # signed decimal, fixed-point shift
    assert fpshift_of(text, lane_z) == 14

    assert flags_of(text, lane_raw) == 0x22  # hex
    assert fpshift_of(text, lane_raw) is None

    assert flags_of(text, "tb.pf.weight[17:0]") == 0x40000024  # unsigned decimal, shifted
    assert fpshift_of(text, "tb.pf.weight[17:0]") == 16

    assert flags_of(text, "tb.pf.count[9:0]") == 0x420  # signed integer: no shift
    assert flags_of(text, "+{count} tb.pf.count[9:0]") == 0x24
    assert "[fpshift_count] 0" not in text


def test_every_fixed_point_trace_gets_its_shift():
    # [fpshift_count] applies to every following trace, so it is repeated for each one.
    traces = [Trace(f"t.s{i}", 15, 0, signed=True, frac_bits=10 + i) for i in range(3)]
    lines = body(render_gtkw(MISSING, [Group("g", traces)]))
    assert lines == [
        "@800200",
        "-g",
        "@40000420",
        "[fpshift_count] 10",
        "t.s0[15:0]",
        "[fpshift_count] 11",
        "t.s1[15:0]",
        "[fpshift_count] 12",
        "t.s2[15:0]",
        "@1000200",
        "-g",
    ]


def test_labels_keep_their_dots_visible():
    text = render_gtkw(MISSING, [Group("g", [Trace("a.b", 3, 0, label="lane0.z x")])])
    assert f"+{{lane0{DOT}z x}} a.b[3:0]" in body(text)
    assert "lane0.z" not in text


def test_deterministic_and_dateless(tmp_path):
    first = render_gtkw(MISSING, GROUPS)
    assert render_gtkw(MISSING, GROUPS) == first
    assert not re.search(r"\b(19|20)\d\d\b|\d\d:\d\d:\d\d", first)
    out = tmp_path / "view.gtkw"
    write_gtkw(out, MISSING, GROUPS)
    assert out.read_text(encoding="utf-8") == first


# --- bit slices ----------------------------------------------------------------------------------


def test_slice_with_declared_range_in_path():
    groups = [
        Group(
            "axis",
            [
                Trace("tb.tdata[31:0]", 15, 8, label="b1", signed=True, frac_bits=6),
                Trace("tb.tdata[31:0]", 31, 0),
                Trace("tb.tdata[31:0]", 31, 31, label="top"),
            ],
        )
    ]
    lines = body(render_gtkw(MISSING, groups))
    slice_line = "+{b1} #{tb.tdata[15:8]} " + bits("tb.tdata[31:0]", range(16, 24))
    assert slice_line in lines
    assert lines[lines.index(slice_line) - 1] == "[fpshift_count] 6"
    assert "tb.tdata[31:0]" in lines  # the whole vector: plain name
    assert "+{top} (0)tb.tdata[31:0]" in lines  # one bit: a plain node, no '#'


def test_slice_bit_numbers_count_from_declared_msb():
    lines = body(render_gtkw(MISSING, [Group("g", [Trace("x.v[39:8]", 11, 8)])]))
    assert "#{x.v[11:8]} " + bits("x.v[39:8]", [28, 29, 30, 31]) in lines


VCD = """$date today $end
$timescale 1ps $end
$scope module TOP $end
$scope module tb $end
$var wire 1 ! clk $end
$var wire 64 " m_axis_tdata [63:0] $end
$var reg 8 # cnt $end
$scope module lanes[3] $end
$var logic 18 $ z [17:0] $end
$upscope $end
$upscope $end
$upscope $end
$enddefinitions $end
#0
0!
"""

DUMP_GROUPS = [
    Group(
        "g",
        [
            Trace("TOP.tb.clk", 0, 0),
            Trace("TOP.tb.m_axis_tdata", 63, 48, label="hi", signed=True, frac_bits=14),
            Trace("TOP.tb.m_axis_tdata", 63, 0),
            Trace("TOP.tb.cnt", 7, 0),
            Trace("TOP.tb.lanes[3].z", 17, 0, signed=True, frac_bits=14),
        ],
    )
]

DUMP_LINES = [
    "TOP.tb.clk",
    "+{hi} #{TOP.tb.m_axis_tdata[63:48]} " + bits("TOP.tb.m_axis_tdata[63:0]", range(16)),
    "TOP.tb.m_axis_tdata[63:0]",
    "TOP.tb.cnt[7:0]",
    "TOP.tb.lanes[3].z[17:0]",
]


def test_slice_ranges_read_from_vcd(tmp_path):
    dump = tmp_path / "dump.vcd"
    dump.write_text(VCD)
    lines = body(render_gtkw(dump, DUMP_GROUPS))
    for line in DUMP_LINES:
        assert line in lines


def fst_hierarchy() -> bytes:
    """The hierarchy of VCD above, as FST hierarchy records (fstapi.c)."""

    def var(name: str, length: int) -> bytes:
        return bytes([16, 0]) + name.encode() + b"\0" + bytes([length, 0])  # logic, implicit dir

    def scope(name: str) -> bytes:
        return bytes([254, 0]) + name.encode() + b"\0" + name.encode() + b"\0"

    return b"".join(
        [
            scope("TOP"),
            scope("tb"),
            bytes([252, 0, 0]) + b"attr\0" + bytes([0]),  # an attribute: skipped
            bytes([253]),
            var("clk", 1),
            var("m_axis_tdata [63:0]", 64),
            var("cnt", 8),  # a vector without a range: [7:0]
            scope("lanes[3]"),
            var("z [17:0]", 18),
            bytes([255, 255, 255]),
        ]
    )


def lz4_literals(data: bytes) -> bytes:
    """An LZ4 block holding ``data`` as one run of literals."""
    n = len(data) - 15
    assert n >= 0
    return bytes([0xF0]) + b"\xff" * (n // 255) + bytes([n % 255]) + data


def fst_file(kind: int, packed: bytes, uclen: int) -> bytes:
    header = bytes([0]) + struct.pack(">Q", 329) + bytes(321)  # FST_BL_HDR, content unread
    geom = bytes([3]) + struct.pack(">Q", 8 + 4) + b"xxxx"  # another block, skipped
    hier = bytes([kind]) + struct.pack(">Q", 16 + len(packed)) + struct.pack(">Q", uclen) + packed
    return header + geom + hier


@pytest.mark.parametrize("kind", ["gzip", "lz4", "lz4duo", "zwrapper"])
def test_slice_ranges_read_from_fst(tmp_path, kind):
    hier = fst_hierarchy()
    if kind == "gzip":
        data = fst_file(4, gzip.compress(hier), len(hier))
    elif kind == "lz4":
        data = fst_file(6, lz4_literals(hier), len(hier))
    elif kind == "lz4duo":
        once = lz4_literals(hier)
        varint = bytes([len(once) & 0x7F | 0x80, len(once) >> 7])  # LEB128, 2 bytes
        data = fst_file(7, varint + lz4_literals(once), len(hier))
    else:
        inner = fst_file(4, gzip.compress(hier), len(hier))
        packed = struct.pack(">Q", len(inner)) + gzip.compress(inner)
        data = bytes([254]) + struct.pack(">Q", 8 + len(packed)) + packed
    dump = tmp_path / "dump.fst"
    dump.write_bytes(data)
    lines = body(render_gtkw(dump, DUMP_GROUPS))
    for line in DUMP_LINES:
        assert line in lines


def test_lz4_matches_overlap_and_long_runs():
    # "abc" + match(offset 3, length 9) + "d": the match copies bytes it is writing.
    assert gtkw._lz4_block(b"\x35abc\x03\x00\x10d", 13) == b"abcabcabcabcd"
    # 20 literals (15 + 5), then match offset 1 of 4 + 15 + 2 = 21 bytes.
    src = b"\xff\x05" + b"0123456789abcdefghij" + b"\x01\x00\x02"
    assert gtkw._lz4_block(src, 41) == b"0123456789abcdefghij" + b"j" * 21


def test_unreadable_dump_warns_and_falls_back(tmp_path):
    dump = tmp_path / "dump.fst"
    dump.write_bytes(bytes([0]) + struct.pack(">Q", 329) + bytes(321) + bytes([4, 0, 0]))
    with pytest.warns(UserWarning, match="declared ranges not read"):
        lines = body(render_gtkw(dump, [Group("g", [Trace("a.b", 7, 0)])]))
    assert "a.b[7:0]" in lines


# --- errors --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("trace", "message"),
    [
        (Trace("a.b", 3, 4), "msb >= lsb"),
        (Trace("a.b", 15, 0, frac_bits=64), "frac_bits"),
        (Trace("a.b", 15, 0, frac_bits=-1), "frac_bits"),
        (Trace("a.b", 79, 0, frac_bits=8), "hex only"),
        (Trace("a.b", 3, 0, label="x}y"), "label"),
        (Trace("a b", 3, 0), "path"),
        (Trace("a.b[7:0]", 11, 4), "outside"),
    ],
)
def test_bad_traces_rejected(trace, message):
    with pytest.raises(ValueError, match=message):
        render_gtkw(MISSING, [Group("g", [trace])])


def test_bad_group_name_rejected():
    with pytest.raises(ValueError, match="group name"):
        render_gtkw(MISSING, [Group("a\nb", [])])


def test_signal_missing_from_dump_rejected(tmp_path):
    dump = tmp_path / "dump.vcd"
    dump.write_text(VCD)
    with pytest.raises(ValueError, match="no such signal"):
        render_gtkw(dump, [Group("g", [Trace("tb.m_axis_tdata", 63, 0)])])  # no TOP. prefix
    with pytest.raises(ValueError, match="1-bit"):
        render_gtkw(dump, [Group("g", [Trace("TOP.tb.clk", 1, 0)])])
