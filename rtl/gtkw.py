"""Write GTKWave save files (``.gtkw``) with grouped, fixed-point-formatted traces.

``gtkwave dump.fst view.gtkw`` then opens with every group in place and every fixed-point field
shown as a decimal real: the raw integer divided by ``2**frac_bits`` (a s1.14 field holding raw
16384 shows ``1``, raw 24576 shows ``1.5``, raw -8192 shows ``-0.5``).

The save-file syntax is GTKWave's own, as written by ``write_save_helper()`` and read back by
``parsewavline()`` in ``src/savefile.c`` (gtkwave/gtkwave; ``gtkwave3/src/savefile.c`` in the 3.3
releases). Each line is one command:

``@<hex>``
    Flags (``TR_*``, below) of every following trace, until the next ``@`` line.
``[fpshift_count] <n>``
    Fixed-point shift of every following trace (0..255), used where ``TR_FPDECSHIFT`` is set.
``-<name>``
    A blank (comment) trace; with ``TR_GRP_BEGIN`` / ``TR_GRP_END`` set it opens / closes the
    group called ``<name>``.
``top.sig[15:0]``
    A whole signal, by its name in the dump. GTKWave names a vector ``scope.name[msb:lsb]`` after
    its declared range, so this form cannot select part of a vector: ``top.sig[11:4]`` is not found
    when ``top.sig`` is declared ``[15:0]`` (the line is dropped without a message).
``#{name} (k)top.sig[15:0] ...``
    A vector called ``name`` assembled from single bits; ``(k)parent`` is bit ``k`` of ``parent``
    counted from its declared msb (``ExtractNodeSingleBit()`` in ``src/bitvec.c``: bit
    ``msb - k`` of a ``[msb:lsb]`` vector). This is how a bit slice is written.
``+{alias} <one of the two forms above>``
    The same trace, shown under ``alias``.

Because a slice needs its parent's declared range, ``render_gtkw`` reads the declared ranges from
the dump's header (FST hierarchy block, or VCD ``$var`` lines) when the dump file exists. A
``Trace.path`` may instead carry the declared range itself (``"grng.m_axis_tdata[63:0]"``), in
which case the dump is not consulted for it. With neither, the trace's own ``[msb:lsb]`` is taken
to be the whole signal.
"""

from __future__ import annotations

import gzip
import io
import math
import re
import struct
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from gpf.outputs import atomic_write_text

__all__ = ["Group", "Trace", "render_gtkw", "write_gtkw"]

# Trace flag bits: `enum TraceEntFlagBits` and the TR_* macros in GTKWave's src/analyzer.h
# (gtkwave/gtkwave; gtkwave3/src/analyzer.h in v3.3.116, same positions in current master).
TR_HIGHLIGHT = 1 << 0
TR_HEX = 1 << 1  # 0x2
TR_DEC = 1 << 2  # 0x4: unsigned decimal
TR_BIN = 1 << 3
TR_OCT = 1 << 4
TR_RJUSTIFY = 1 << 5  # 0x20: GTKWave's default for every trace
TR_BLANK = 1 << 9  # 0x200: blank / comment line (group begin and end markers are blanks)
TR_SIGNED = 1 << 10  # 0x400: signed decimal (GTKWave's "Signed Decimal" sets it without TR_DEC)
TR_CLOSED = 1 << 22  # 0x400000: group shown collapsed
TR_GRP_BEGIN = 1 << 23  # 0x800000
TR_GRP_END = 1 << 24  # 0x1000000
TR_FPDECSHIFT = 1 << 30  # 0x40000000: decimal shown as value / 2**[fpshift_count]

FLAGS_HEX = TR_RJUSTIFY | TR_HEX  # @22
FLAGS_UDEC = TR_RJUSTIFY | TR_DEC  # @24
FLAGS_SDEC = TR_RJUSTIFY | TR_SIGNED  # @420
FLAGS_UFIX = FLAGS_UDEC | TR_FPDECSHIFT  # @40000024
FLAGS_SFIX = FLAGS_SDEC | TR_FPDECSHIFT  # @40000420
FLAGS_GROUP_BEGIN = TR_BLANK | TR_GRP_BEGIN  # @800200
FLAGS_GROUP_END = TR_BLANK | TR_GRP_END  # @1000200

# GTKWave decimal conversions work on a 64-bit integer; wider vectors fall back to hex.
MAX_DECIMAL_WIDTH = 64

# GTKWave's stock settings (hier_max_level 1, vanilla_rc() in src/rc.c) show only the text after the
# last '.' of a name, aliases included, so "lane0.z" and "lane1.z" would both read "z". Dots in
# labels are therefore written as U+2024 ONE DOT LEADER, which looks the same but is not '.'.
LABEL_DOT = "\u2024"

_RANGE_RE = re.compile(r"^(?P<base>.*)\[(?P<msb>-?\d+):(?P<lsb>-?\d+)\]$")

# A declared range: (msb, lsb) of a vector, or None for a scalar (1-bit, no range).
Declared = tuple[int, int] | None


@dataclass(frozen=True)
class Trace:
    path: str  # full hierarchical signal name as it appears in the FST, e.g. "grng.m_axis_tdata"
    msb: int  # bit range [msb:lsb] to show (a slice of a wider bus is allowed)
    lsb: int
    label: str | None = None  # alias shown in the viewer, e.g. "lane0.z"
    signed: bool = False
    frac_bits: int | None = None  # None: show as hex; int: fixed-point decimal, this many frac bits


@dataclass(frozen=True)
class Group:
    name: str
    traces: list[Trace]


def write_gtkw(path: Path, dumpfile: Path, groups: list[Group],
               window_ps: int | None = None) -> None:
    """Write the save file for ``dumpfile`` to ``path`` (see ``render_gtkw``)."""
    atomic_write_text(path, render_gtkw(dumpfile, groups, window_ps))


def render_gtkw(dumpfile: Path, groups: list[Group], window_ps: int | None = None) -> str:
    """Return the text of a GTKWave save file showing ``groups`` of ``dumpfile``.

    The text depends only on the arguments and on the dump's header (no dates, no window state).
    ``[dumpfile]`` is written as given: a dump named on GTKWave's command line takes precedence,
    and GTKWave resolves a relative one from its working directory.
    """
    dumpfile = Path(dumpfile)
    _check_text("dumpfile", str(dumpfile))
    declared = _read_declared(dumpfile)
    lines = [
        "[*]",
        "[*] GTKWave save file written by gpf.rtl.gtkw",
        "[*]",
        f'[dumpfile] "{dumpfile}"',
    ]
    if window_ps is not None:
        # GTKWave 3.3 shows about 2^(-zoom - 7.6) ps per pixel in the ~1050-pixel wave pane of
        # a 1600-pixel window (measured on screenshots of 1 ps-resolution FSTs)
        zoom = -(math.log2(window_ps / 1050) + 7.6)
        lines += ["[size] 1600 1000", f"*{zoom:.3f} 0"]
    flags_now: int | None = None

    def set_flags(flags: int) -> None:
        nonlocal flags_now
        if flags != flags_now:
            lines.append(f"@{flags:x}")
            flags_now = flags

    for group in groups:
        _check_text("group name", group.name)
        set_flags(FLAGS_GROUP_BEGIN)
        lines.append(f"-{group.name}")
        for trace in group.traces:
            flags = _trace_flags(trace)
            set_flags(flags)
            if flags & TR_FPDECSHIFT:
                lines.append(f"[fpshift_count] {trace.frac_bits}")
            lines.append(_trace_line(trace, declared, dumpfile))
        set_flags(FLAGS_GROUP_END)
        lines.append(f"-{group.name}")
    return "\n".join(lines) + "\n"


def _trace_flags(trace: Trace) -> int:
    if trace.frac_bits is None:
        return FLAGS_HEX
    width = trace.msb - trace.lsb + 1
    if not 0 <= trace.frac_bits < MAX_DECIMAL_WIDTH:
        raise ValueError(f"{trace.path}: frac_bits {trace.frac_bits} not in 0..63")
    if width > MAX_DECIMAL_WIDTH:
        raise ValueError(
            f"{trace.path}[{trace.msb}:{trace.lsb}]: GTKWave shows vectors wider than "
            f"{MAX_DECIMAL_WIDTH} bits in hex only"
        )
    if trace.frac_bits == 0:
        return FLAGS_SDEC if trace.signed else FLAGS_UDEC
    return FLAGS_SFIX if trace.signed else FLAGS_UFIX


def _trace_line(trace: Trace, declared: dict[str, Declared] | None, dumpfile: Path) -> str:
    if trace.msb < trace.lsb or trace.lsb < 0:
        raise ValueError(f"{trace.path}: range [{trace.msb}:{trace.lsb}] must have msb >= lsb >= 0")
    _check_text("path", trace.path, forbid="{} \t")
    alias = ""
    if trace.label is not None:
        _check_text("label", trace.label, forbid="{}")
        alias = "+{" + trace.label.replace(".", LABEL_DOT) + "} "

    match = _RANGE_RE.match(trace.path)
    if match:  # the path carries its declared range
        base = match["base"]
        decl: Declared = (int(match["msb"]), int(match["lsb"]))
    elif declared is not None:
        base = trace.path
        if base not in declared:
            raise ValueError(f"{base}: no such signal in {dumpfile}")
        decl = declared[base]
    else:  # no dump to look at: assume the trace is the whole signal
        base = trace.path
        decl = None if trace.msb == trace.lsb == 0 else (trace.msb, trace.lsb)

    if decl is None:
        if trace.msb != 0 or trace.lsb != 0:
            raise ValueError(f"{base} is a 1-bit signal, not [{trace.msb}:{trace.lsb}]")
        return f"{alias}{base}"
    dmsb, dlsb = decl
    parent = f"{base}[{dmsb}:{dlsb}]"
    if (trace.msb, trace.lsb) == (dmsb, dlsb):
        return f"{alias}{parent}"
    lo, hi = min(dmsb, dlsb), max(dmsb, dlsb)
    if not (lo <= trace.lsb and trace.msb <= hi):
        raise ValueError(f"{base}[{trace.msb}:{trace.lsb}] is outside {parent}")
    # (k) counts from the declared msb: bit b is k = |dmsb - b|.
    bits = " ".join(f"({abs(dmsb - b)}){parent}" for b in range(trace.msb, trace.lsb - 1, -1))
    if trace.msb == trace.lsb:  # a single bit is a plain node, drawn as a logic waveform
        return f"{alias}{bits}"
    return f"{alias}#{{{base}[{trace.msb}:{trace.lsb}]}} {bits}"


def _check_text(what: str, text: str, forbid: str = "") -> None:
    bad = set(text) & set(forbid + "\n\r")
    if not text or bad:
        raise ValueError(f"{what} {text!r}: must be non-empty, without {sorted(bad)}")


# --- declared ranges from the dump header ---------------------------------------------------


def _read_declared(dumpfile: Path) -> dict[str, Declared] | None:
    """Map each signal's full name (without range) to its declared range.

    None when the dump is missing or its header cannot be read (then a warning says why).
    """
    try:
        with open(dumpfile, "rb") as f:
            head = f.read(1)
            f.seek(0)
            if head and head[0] in (_FST_BL_HDR, _FST_BL_ZWRAPPER):
                names = _fst_vars(f)
            elif head.isspace() or head == b"$":
                names = _vcd_vars(f)
            else:
                raise ValueError("neither FST nor VCD")
            return _declared_from_names(names)
    except FileNotFoundError:
        return None
    except (OSError, ValueError, IndexError, EOFError, struct.error, zlib.error) as exc:
        warnings.warn(
            f"{dumpfile}: declared ranges not read ({exc}); bit slices need the range in the path",
            stacklevel=3,
        )
        return None


def _declared_from_names(names: list[tuple[str, int]]) -> dict[str, Declared]:
    """GTKWave's naming (extractNextVar() in src/fst.c): spaces dropped, a trailing [msb:lsb]
    is the declared range, a vector without one is [length-1:0]."""
    out: dict[str, Declared] = {}
    for raw, length in names:
        name = raw.replace(" ", "")
        match = _RANGE_RE.match(name)
        if match:
            out.setdefault(match["base"], (int(match["msb"]), int(match["lsb"])))
        else:
            out.setdefault(name, (length - 1, 0) if length > 1 else None)
    return out


def _vcd_vars(f: BinaryIO) -> list[tuple[str, int]]:
    words: list[str] = []
    for raw in f:
        line = raw.decode("latin-1").split()
        words += line
        if "$enddefinitions" in line:
            break
    scopes: list[str] = []
    names: list[tuple[str, int]] = []
    i = 0
    while i < len(words):
        try:
            end = words.index("$end", i)
        except ValueError:
            end = len(words)
        if words[i] == "$scope":
            scopes.append(words[i + 2])
        elif words[i] == "$upscope":
            scopes.pop()
        elif words[i] == "$var":  # $var <type> <size> <id> <ref> [range] $end
            names.append((".".join([*scopes, "".join(words[i + 4 : end])]), int(words[i + 2])))
        i = end + 1
    return names


# FST block and hierarchy tags: src/helpers/fst/fstapi.h (enum fstBlockType, fstHierType).
_FST_BL_HDR = 0
_FST_BL_HIER = 4
_FST_BL_HIER_LZ4 = 6
_FST_BL_HIER_LZ4DUO = 7
_FST_BL_ZWRAPPER = 254
_FST_VT_MAX = 29
_FST_ST_GEN_ATTRBEGIN = 252
_FST_ST_GEN_ATTREND = 253
_FST_ST_VCD_SCOPE = 254
_FST_ST_VCD_UPSCOPE = 255


def _fst_vars(f: BinaryIO) -> list[tuple[str, int]]:
    """(full name, length) of every variable in an FST file's hierarchy block.

    Blocks: kind byte, u64 length counting itself, body. The hierarchy is written last, when the
    simulator closes the file."""
    while head := f.read(9):
        if len(head) < 9:
            break
        kind = head[0]
        (seclen,) = struct.unpack(">Q", head[1:])
        if kind == _FST_BL_ZWRAPPER:  # whole file gzip-wrapped: u64 length, gzip stream
            return _fst_vars(io.BytesIO(gzip.decompress(f.read(seclen - 8)[8:])))
        if kind not in (_FST_BL_HIER, _FST_BL_HIER_LZ4, _FST_BL_HIER_LZ4DUO):
            f.seek(seclen - 8, io.SEEK_CUR)
            continue
        body = f.read(seclen - 8)  # u64 unpacked length, packed hierarchy
        (uclen,) = struct.unpack_from(">Q", body, 0)
        packed = body[8:]
        if kind == _FST_BL_HIER:
            hier = gzip.decompress(packed)
        elif kind == _FST_BL_HIER_LZ4:
            hier = _lz4_block(packed, uclen)
        else:  # LZ4 applied twice; the varint length of the middle stage comes first
            uclen2, skip = _varint(packed, 0)
            hier = _lz4_block(_lz4_block(packed[skip:], uclen2), uclen)
        return _fst_hier(hier)
    raise ValueError("no hierarchy block (is the simulation still writing it?)")


def _fst_hier(data: bytes) -> list[tuple[str, int]]:
    # Record layout: fstReaderIterateHier() in src/helpers/fst/fstapi.c.
    scopes: list[str] = []
    names: list[tuple[str, int]] = []
    pos = 0
    while pos < len(data):
        tag = data[pos]
        pos += 1
        if tag == _FST_ST_VCD_SCOPE:  # type, name\0, component\0
            name, pos = _cstr(data, pos + 1)
            _, pos = _cstr(data, pos)
            scopes.append(name)
        elif tag == _FST_ST_VCD_UPSCOPE:
            scopes.pop()
        elif tag == _FST_ST_GEN_ATTRBEGIN:  # type, subtype, name\0, varint
            _, pos = _cstr(data, pos + 2)
            _, pos = _varint(data, pos)
        elif tag == _FST_ST_GEN_ATTREND:
            pass
        elif tag <= _FST_VT_MAX:  # var: direction, name\0, varint length, varint alias
            name, pos = _cstr(data, pos + 1)
            length, pos = _varint(data, pos)
            _, pos = _varint(data, pos)
            names.append((".".join([*scopes, name]), length))
        else:
            raise ValueError(f"unknown FST hierarchy tag {tag}")
    return names


def _cstr(data: bytes, pos: int) -> tuple[str, int]:
    end = data.index(0, pos)
    return data[pos:end].decode("latin-1"), end + 1


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, pos


def _lz4_block(src: bytes, size: int) -> bytes:
    """Decode one raw LZ4 block (no frame header) of ``size`` decoded bytes."""
    out = bytearray()
    pos = 0
    while pos < len(src) and len(out) < size:
        token = src[pos]
        pos += 1
        count = token >> 4
        if count == 15:
            while True:
                count += src[pos]
                pos += 1
                if src[pos - 1] != 255:
                    break
        out += src[pos : pos + count]
        pos += count
        if pos >= len(src) or len(out) >= size:
            break
        offset = src[pos] | src[pos + 1] << 8
        pos += 2
        count = token & 15
        if count == 15:
            while True:
                count += src[pos]
                pos += 1
                if src[pos - 1] != 255:
                    break
        count += 4
        start = len(out) - offset
        if offset == 0 or start < 0:
            raise ValueError("corrupt LZ4 block")
        chunk = out[start : start + count]
        out += (chunk * (count // len(chunk) + 1))[:count]  # the match may overlap its output
    return bytes(out[:size])
