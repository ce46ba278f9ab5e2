"""Tests of gpf.rtl.gtkw: the text of the GTKWave save files it renders (through pyvcd's
GTKWSave), the translate filter files beside them, and the dumps it reads (through pywellen)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from gpf.rtl import gtkw
from gpf.rtl.gtkw import (
    Bits,
    Dump,
    Group,
    Names,
    Trace,
    Window,
    keep_declared,
    render_filters,
    render_gtkw,
    write_gtkw,
)

DOT = gtkw.LABEL_DOT
DATA = Path(__file__).parent / "data"


def body(text: str) -> list[str]:
    """The lines after the header: from the first flags ('@') line on."""
    lines = text.splitlines()
    return lines[[i for i, line in enumerate(lines) if line.startswith("@")][0] :]


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
    """The [fpshift_count] in force where ``trace_line`` appears, if it was written for it:
    GTKWave applies the last one to every following trace, so each fixed-point trace needs its
    own between it and the trace before it."""
    lines = body(text)
    i = lines.index(trace_line)
    for line in reversed(lines[:i]):
        if match := re.fullmatch(r"\[fpshift_count\] (\d+)", line):
            return int(match[1])
        if not line.startswith("@"):
            return None
    return None


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
    # Bit positions of enum TraceEntFlagBits in GTKWave's src/analyzer.h (through pyvcd's GTKWFlag).
    assert gtkw.TR_HEX == 0x2
    assert gtkw.TR_DEC == 0x4
    assert gtkw.TR_RJUSTIFY == 0x20
    assert gtkw.TR_BLANK == 0x200
    assert gtkw.TR_SIGNED == 0x400
    assert gtkw.TR_FTRANSLATED == 0x2000
    assert gtkw.TR_CLOSED == 0x400000
    assert gtkw.TR_GRP_BEGIN == 0x800000
    assert gtkw.TR_GRP_END == 0x1000000
    assert gtkw.TR_FPDECSHIFT == 0x40000000


# --- layout --------------------------------------------------------------------------------------


def test_header_dumpfile_and_window_size():
    text = render_gtkw(Path("build/sim/dump.fst"), GROUPS)
    lines = text.splitlines()
    assert text.endswith("\n")
    assert '[dumpfile] "build/sim/dump.fst"' in lines
    assert all(line.startswith("[*]") for line in lines[:3])
    assert f"[size] {gtkw.WINDOW_SIZE[0]} {gtkw.WINDOW_SIZE[1]}" in lines
    assert f"[signals_width] {gtkw.SIGNALS_WIDTH}" in lines
    assert "[sst_expanded] 0" in lines
    assert not any(line.startswith(("[timestart]", "*")) for line in lines)  # no window asked


def walk_groups(text: str) -> list[str]:
    """Check that every group (ours and each combined vector's) closes, in order; return the
    names of ours as opened."""
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
        elif line.startswith("[") or line.startswith("^"):
            continue
        elif "#{" in line:  # a combined vector: a group of its bits, ended by "-group_end"
            assert stack, f"{line!r} outside any group"
            assert flags is not None and flags & gtkw.TR_GRP_BEGIN
            stack.append("group_end")
        else:
            assert stack, f"{line!r} outside any group"
    assert stack == []
    return opened


def test_groups_balanced_and_named():
    text = render_gtkw(MISSING, GROUPS)
    assert walk_groups(text) == ["grng", "state", "empty"]
    lines = body(text)
    assert lines.count("@800200") == 3
    assert lines.count("@1000200") == 3


def test_nested_and_closed_groups():
    groups = [Group("outer", [Trace("a.b", 0, 0), Group("inner", [Trace("a.c", 3, 0)],
                                                          closed=True)])]
    text = render_gtkw(MISSING, groups)
    assert walk_groups(text) == ["outer", "inner"]
    lines = body(text)
    i = lines.index("-inner")
    assert int(lines[i - 1][1:], 16) & gtkw.TR_CLOSED  # the folded group's begin marker
    assert not int(lines[lines.index("-outer") - 1][1:], 16) & gtkw.TR_CLOSED


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
        "[fpshift_count] 10",
        "@40000420",
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
    assert write_gtkw(out, MISSING, GROUPS) == [out]  # no names: no filter files
    assert out.read_text(encoding="utf-8") == first


# --- the window ----------------------------------------------------------------------------------


@pytest.mark.parametrize("span", [10_000, 240_000, 5_000_000])
def test_window_zoom_shows_the_span_in_the_wave_pane(span):
    # GTKWave's calczoom(): zoom z shows 2^-z time units in 200 pixels.
    zoom = Window(1000, 1000 + span).zoom
    assert 2 ** -zoom / gtkw.PIXELS_PER_FRAME * gtkw.WAVE_PANE == pytest.approx(span)


def test_window_lines():
    lines = render_gtkw(MISSING, GROUPS, Window(1500, 9500, marker=4000)).splitlines()
    assert "[timestart] 1500" in lines
    (zoom_line,) = [line for line in lines if line.startswith("*")]
    zoom, marker, *named = zoom_line[1:].split()
    assert float(zoom) == pytest.approx(Window(1500, 9500).zoom, abs=1e-6)
    assert int(marker) == 4000 and named == ["-1"] * 26
    no_marker = render_gtkw(MISSING, GROUPS, Window(0, 100)).splitlines()
    assert [line for line in no_marker if line.startswith("*")][0].split()[1] == "-1"
    assert "[timestart] 0" in no_marker


def test_window_before_time_zero_starts_at_zero():
    assert "[timestart] 0" in render_gtkw(MISSING, GROUPS, Window(-50, 100)).splitlines()


# --- named values: translate filter files --------------------------------------------------------

STATES = Names("state", ((0, "S_IDLE"), (1, "S_RUN"), (10, "S_OUT")))


def test_filter_file_text_and_place(tmp_path):
    save = tmp_path / "v.gtkw"
    groups = [Group("g", [Trace("a.state", 3, 0, label="state", names=STATES)])]
    files = render_filters(groups, save)
    path = (tmp_path / "v.state.txt").resolve()
    assert files == {path: "0 S_IDLE\n1 S_RUN\na S_OUT\n"}  # hex, as the trace shows them
    assert gtkw.filter_path(save, STATES) == path


def test_named_trace_references_its_filter_and_is_a_combined_vector(tmp_path):
    # A file filter on a signal the FST declares an enum is ignored by GTKWave 3.3.118 (Verilator
    # writes ctrl's state_t so); a vector combined from its bits takes it.
    save = tmp_path / "v.gtkw"
    groups = [Group("g", [Trace("a.state", 3, 0, label="state", names=STATES)])]
    lines = body(render_gtkw(MISSING, groups, savefile=save))
    trace = "+{state} #{a.state[3:0]} " + bits("a.state[3:0]", range(4))
    i = lines.index(trace)
    assert lines[i - 1] == f"^1 {gtkw.filter_path(save, STATES)}"
    flags = int(lines[i - 2][1:], 16)
    assert flags & gtkw.TR_FTRANSLATED and flags & gtkw.TR_HEX
    assert not flags & (gtkw.TR_FPDECSHIFT | gtkw.TR_DEC)
    assert lines[i + 1 : i + 3] == ["@1001200", "-group_end"]


def test_named_single_bit_is_a_plain_trace(tmp_path):
    names = Names("onoff", ((0, "off"), (1, "on")))
    lines = body(render_gtkw(MISSING, [Group("g", [Trace("a.en", 0, 0, names=names)])],
                             savefile=tmp_path / "v.gtkw"))
    assert "a.en" in lines
    assert lines[lines.index("a.en") - 1].startswith("^1 ")


def test_filters_written_beside_the_save_file_and_shared(tmp_path):
    save = tmp_path / "v.gtkw"
    groups = [Group("g", [Trace("a.s", 3, 0, names=STATES), Trace("a.t", 3, 0, names=STATES)])]
    written = write_gtkw(save, MISSING, groups)
    assert written == [save, gtkw.filter_path(save, STATES)]
    assert written[1].read_text() == "0 S_IDLE\n1 S_RUN\na S_OUT\n"
    text = save.read_text()
    assert text.count("^1 ") == 2 and "^2 " not in text  # one filter, numbered once


def test_one_names_file_cannot_hold_two_lists(tmp_path):
    other = Names("state", ((0, "A"),))
    groups = [Group("g", [Trace("a.s", 3, 0, names=STATES), Trace("a.t", 3, 0, names=other)])]
    with pytest.raises(ValueError, match="two different value lists"):
        render_filters(groups, tmp_path / "v.gtkw")


HANDSHAKE = Names("hs", ((0, "idle"), (1, "ready"), (2, "stall"), (3, "beat")))


def test_bits_combine_scalars_with_names(tmp_path):
    save = tmp_path / "v.gtkw"
    groups = [Group("g", [Bits("a -> b", ("t.v", "t.r"), HANDSHAKE)])]
    lines = body(render_gtkw(MISSING, groups, savefile=save))
    i = lines.index("#{a -> b} t.v t.r")  # valid is the most significant bit
    assert lines[i - 1] == f"^1 {gtkw.filter_path(save, HANDSHAKE)}"
    assert int(lines[i - 2][1:], 16) & gtkw.TR_FTRANSLATED
    assert render_filters(groups, save)[gtkw.filter_path(save, HANDSHAKE)] == \
        "0 idle\n1 ready\n2 stall\n3 beat\n"


def test_bits_need_existing_one_bit_signals(tmp_path):
    dump = tmp_path / "dump.vcd"
    dump.write_text(VCD)
    ok = [Group("g", [Bits("hs", ("TOP.tb.clk", "TOP.tb.clk"))])]
    assert "#{hs} TOP.tb.clk TOP.tb.clk" in body(render_gtkw(dump, ok))
    with pytest.raises(ValueError, match="not a 1-bit signal"):
        render_gtkw(dump, [Group("g", [Bits("hs", ("TOP.tb.clk", "TOP.tb.cnt"))])])
    with pytest.raises(ValueError, match="no such signal"):
        render_gtkw(dump, [Group("g", [Bits("hs", ("TOP.tb.nope",))])])


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
    text = render_gtkw(MISSING, groups)
    lines = body(text)
    slice_line = "+{b1} #{tb.tdata[15:8]} " + bits("tb.tdata[31:0]", range(16, 24))
    assert slice_line in lines
    assert fpshift_of(text, slice_line) == 6
    assert flags_of(text, slice_line) & gtkw.TR_FPDECSHIFT
    assert "tb.tdata[31:0]" in lines  # the whole vector: plain name
    assert "+{top} (0)tb.tdata[31:0]" in lines  # one bit: a plain node, no '#'


def test_slice_bit_numbers_count_from_declared_msb():
    lines = body(render_gtkw(MISSING, [Group("g", [Trace("x.v[39:8]", 11, 8)])]))
    assert "#{x.v[11:8]} " + bits("x.v[39:8]", [28, 29, 30, 31]) in lines


# tests/data/gtkw_dump.fst.bin is `vcd2fst` (GTKWave 3.3.118) of this text: an FST (named .bin,
# as .gitignore drops *.fst; pywellen tells the format from the content).
VCD = """$timescale 1ps $end
$scope module TOP $end
$scope module tb $end
$var wire 1 ! clk $end
$var wire 64 " m_axis_tdata [63:0] $end
$var reg 8 # cnt $end
$var wire 1 % valid $end
$var wire 1 & ready $end
$scope module lanes[3] $end
$var logic 18 $ z [17:0] $end
$upscope $end
$upscope $end
$upscope $end
$enddefinitions $end
#0
0!
b0 "
b0 #
0%
0&
b0 $
#10
1%
#20
1&
#30
0%
#40
1%
#50
0%
0&
#60
1%
1&
#70
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

DECLARED = {"TOP.tb.clk": None, "TOP.tb.m_axis_tdata": (63, 0), "TOP.tb.cnt": (7, 0),
            "TOP.tb.valid": None, "TOP.tb.ready": None, "TOP.tb.lanes[3].z": (17, 0)}


@pytest.fixture(params=["vcd", "fst"])
def dump(request, tmp_path) -> Path:
    if request.param == "fst":
        return DATA / "gtkw_dump.fst.bin"
    path = tmp_path / "dump.vcd"
    path.write_text(VCD)
    return path


def test_declared_ranges_read_from_the_dump(dump):
    assert Dump(dump).declared() == DECLARED
    lines = body(render_gtkw(dump, DUMP_GROUPS))
    for line in DUMP_LINES:
        assert line in lines


def test_dump_changes_and_handshakes(dump):
    d = Dump(dump)
    assert "TOP.tb.valid" in d and "TOP.tb.nope" not in d
    assert d.changes("TOP.tb.valid") == [(0, 0), (10, 1), (30, 0), (40, 1), (50, 0), (60, 1)]
    # both high at 20 (ready joins), 40 (valid again), 60 (both at once)
    assert d.all_high("TOP.tb.valid", "TOP.tb.ready") == [20, 40, 60]
    assert d.all_high("TOP.tb.valid") == [10, 40, 60]


def test_unreadable_dump_warns_and_falls_back(tmp_path):
    dump = tmp_path / "dump.fst"
    dump.write_bytes(b"\0" * 9 + b"not an FST at all")
    with pytest.raises(ValueError, match="not a readable FST or VCD"):
        Dump(dump)
    with pytest.warns(UserWarning, match="declared ranges not read"):
        lines = body(render_gtkw(dump, [Group("g", [Trace("a.b", 7, 0)])]))
    assert "a.b[7:0]" in lines


def test_no_hand_written_dump_parsers():
    # FST and VCD are read by pywellen: no block decoder or header parser of our own.
    source = Path(gtkw.__file__).read_text()
    for name in ("lz4", "gzip", "zlib", "struct", "$enddefinitions", "$var"):
        assert name not in source, name


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
        (Bits("x{", ("a.b",)), "label"),
        (Bits("x", ()), "no signals"),
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


def test_netlist_view_keeps_what_the_dump_declares(dump):
    # a netlist's dump lacks wires synthesis merged: those traces (a combined vector whole, a
    # group left empty) go, named; what stays renders without error
    groups = [Group("g", [Trace("TOP.tb.clk", 0, 0), Trace("TOP.tb.gone", 3, 0),
                          Trace("TOP.tb.cnt[7:0]", 3, 0),
                          Bits("hs", ("TOP.tb.valid", "TOP.tb.merged")),
                          Group("inner", [Trace("TOP.tb.also_gone", 0, 0)])]),
              Group("kept", [Bits("hs", ("TOP.tb.valid", "TOP.tb.ready"))])]
    with pytest.raises(ValueError, match="no such signal"):
        render_gtkw(dump, groups)
    kept, missing = keep_declared(groups, Dump(dump).declared())
    assert missing == ["TOP.tb.also_gone", "TOP.tb.gone", "TOP.tb.merged"]
    assert kept == [Group("g", [Trace("TOP.tb.clk", 0, 0), Trace("TOP.tb.cnt[7:0]", 3, 0)]),
                    groups[1]]
    lines = body(render_gtkw(dump, kept))
    assert "TOP.tb.clk" in lines and not any("gone" in line for line in lines)


def test_zoom_is_finite_for_an_empty_window():
    assert math.isfinite(Window(5, 5).zoom)
