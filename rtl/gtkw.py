"""Write GTKWave save files (``.gtkw``) with grouped, fixed-point-formatted traces.

``gtkwave dump.fst view.gtkw`` then opens with every group in place and every fixed-point field
shown as a decimal real: the raw integer divided by ``2**frac_bits`` (a s1.14 field holding raw
16384 shows ``1``, raw 24576 shows ``1.5``, raw -8192 shows ``-0.5``).

Libraries do the work: pyvcd's ``vcd.gtkw.GTKWSave`` writes the save file (groups, flags, aliases,
translate filters, combined vectors, zoom and markers) and ``make_translation_filter`` the
filter files; pywellen reads the dump's hierarchy (FST or VCD: each variable's name and width)
and its value changes. What stays here is what neither has:

* ``[fpshift_count] <n>``: GTKWSave has the ``fpdecshift`` flag but no line for its shift;
  GTKWave (``parsewavline()`` in ``src/savefile.c``) applies it to every following trace.
* GTKWave's naming: a vector is ``scope.name[msb:lsb]`` after its declared range, and a bit
  slice is a vector combined from single bits ``(k)parent``, k counted from the declared msb
  (``ExtractNodeSingleBit()`` in ``src/bitvec.c``). pywellen gives widths, not declared ranges:
  a vector of width w is taken as ``[w-1:0]``, as every vector the generator writes is. A
  ``Trace.path`` may carry another declared range itself (``"tb.v[39:8]"``); the dump is then
  not consulted for it. With no dump to read, the trace's own ``[msb:lsb]`` is taken to be the
  whole signal.
* a named trace of a multi-bit signal is written as a vector combined from its bits: GTKWave
  3.3.118 shows a signal the FST declares an enum (Verilator's ctrl ``state_t``) through the
  FST's own table only, never through a filter file.
* labels with dots, and the zoom that shows a given time window (``Window``).
"""

from __future__ import annotations

import io
import math
import re
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pywellen
from vcd.gtkw import GTKWFlag, GTKWSave, make_translation_filter

from gpf.outputs import atomic_write_text

__all__ = ["Bits", "Dump", "Group", "Names", "Trace", "Window", "filter_path", "render_filters",
           "render_gtkw", "write_gtkw"]

# Trace flag bits: `enum TraceEntFlagBits` and the TR_* macros in GTKWave's src/analyzer.h;
# pyvcd's GTKWFlag holds the same bits.
TR_HEX = GTKWFlag.hex.value  # 0x2
TR_DEC = GTKWFlag.dec.value  # 0x4: unsigned decimal
TR_RJUSTIFY = GTKWFlag.rjustify.value  # 0x20: GTKWave's default for every trace
TR_BLANK = GTKWFlag.blank.value  # 0x200: blank / comment line (group begin and end markers)
TR_SIGNED = GTKWFlag.signed.value  # 0x400: signed decimal
TR_FTRANSLATED = GTKWFlag.ftranslated.value  # 0x2000: values shown through a filter file
TR_CLOSED = GTKWFlag.closed.value  # 0x400000: group shown collapsed
TR_GRP_BEGIN = GTKWFlag.grp_begin.value  # 0x800000
TR_GRP_END = GTKWFlag.grp_end.value  # 0x1000000
TR_FPDECSHIFT = GTKWFlag.fpdecshift.value  # 0x40000000: decimal shown as value / 2**shift

# GTKWave decimal conversions work on a 64-bit integer; wider vectors fall back to hex.
MAX_DECIMAL_WIDTH = 64

# GTKWave's stock settings (hier_max_level 1, vanilla_rc() in src/rc.c) show only the text after the
# last '.' of a name, aliases included, so "lane0.z" and "lane1.z" would both read "z". Dots in
# labels are therefore written as U+2024 ONE DOT LEADER, which looks the same but is not '.'.
LABEL_DOT = "\u2024"

# The window the save file asks for (a window manager shrinks it to a smaller screen), and the
# width of its waves pane: the window less the signals pane (SIGNALS_WIDTH), the folded search
# tree's strip, borders and scroll bar (65 pixels, measured on GTKWave 3.3.118 screenshots).
WINDOW_SIZE = (1600, 1400)
SIGNALS_WIDTH = 420
WAVE_PANE = WINDOW_SIZE[0] - SIGNALS_WIDTH - 65
# GTKWave's calczoom(): a zoom z shows 2^-z dump time units in 200 pixels (zoombase 2).
PIXELS_PER_FRAME = 200

_RANGE_RE = re.compile(r"^(?P<base>.*)\[(?P<msb>-?\d+):(?P<lsb>-?\d+)\]$")

# A declared range: (msb, lsb) of a vector, or None for a scalar (1-bit, no range).
Declared = tuple[int, int] | None


@dataclass(frozen=True)
class Names:
    """Names for a trace's values, through a GTKWave translate filter file: ``name`` names the
    file (``<view>.<name>.txt`` beside the .gtkw), ``values`` maps raw values to names."""

    name: str
    values: tuple[tuple[int, str], ...]


@dataclass(frozen=True)
class Trace:
    path: str  # full hierarchical signal name as it appears in the FST, e.g. "grng.m_axis_tdata"
    msb: int  # bit range [msb:lsb] to show (a slice of a wider bus is allowed)
    lsb: int
    label: str | None = None  # alias shown in the viewer, e.g. "lane0.z"
    signed: bool = False
    frac_bits: int | None = None  # None: show as hex; int: fixed-point decimal, this many frac bits
    names: Names | None = None  # show named values (in hex where none is named)


@dataclass(frozen=True)
class Bits:
    """1-bit signals shown as one vector, the first most significant (GTKWave's Combine Down),
    e.g. a stream's {tvalid, tready} with ``names`` for its four values."""

    label: str
    paths: tuple[str, ...]
    names: Names | None = None


@dataclass(frozen=True)
class Group:
    name: str
    traces: list[Trace | Bits | Group]  # a group may hold groups
    closed: bool = False  # shown folded


@dataclass(frozen=True)
class Window:
    """The time the view opens on, in the dump's time units, with the primary marker."""

    start: int
    end: int
    marker: int | None = None

    @property
    def zoom(self) -> float:
        per_pixel = max(self.end - self.start, 1) / WAVE_PANE
        return -math.log2(per_pixel * PIXELS_PER_FRAME)


def filter_path(savefile: Path, names: Names) -> Path:
    """Where the translate filter file of ``names`` lives: beside the save file, absolute (GTKWave
    opens it from its own working directory)."""
    return Path(savefile).resolve().with_name(f"{Path(savefile).stem}.{names.name}.txt")


def write_gtkw(path: Path, dumpfile: Path, groups: list[Group],
               window: Window | None = None) -> list[Path]:
    """Write the save file for ``dumpfile`` to ``path`` (see ``render_gtkw``) and its translate
    filter files beside it; return the paths written, the save file first."""
    filters = render_filters(groups, path)
    text = render_gtkw(dumpfile, groups, window, savefile=path)
    for fpath, ftext in filters.items():
        atomic_write_text(fpath, ftext)
    atomic_write_text(path, text)
    return [Path(path), *filters]


def keep_declared(groups: list[Group], declared: dict[str, Declared]
                  ) -> tuple[list[Group], list[str]]:
    """``groups`` without the traces naming a signal ``declared`` (a dump's) lacks, and the names
    left out: a synthesized netlist keeps its ports but may rename or merge internal wires. A
    combined vector goes whole if one of its bits is missing; a group left empty goes too."""
    missing: list[str] = []

    def present(path: str) -> bool:
        match = _RANGE_RE.match(path)
        base = match["base"] if match else path
        if base not in declared:
            missing.append(base)
            return False
        return True

    def keep(items: list[Trace | Bits | Group]) -> list[Trace | Bits | Group]:
        out: list[Trace | Bits | Group] = []
        for item in items:
            if isinstance(item, Group):
                inner = keep(item.traces)
                if inner:
                    out.append(Group(item.name, inner, item.closed))
            elif isinstance(item, Bits):
                if all([present(path) for path in item.paths]):
                    out.append(item)
            elif present(item.path):
                out.append(item)
        return out

    kept = keep(list(groups))
    return kept, sorted(set(missing))


def render_filters(groups: list[Group], savefile: Path) -> dict[Path, str]:
    """The translate filter files the traces of ``groups`` use: path -> text."""
    out: dict[Path, str] = {}
    for trace in _traces(groups):
        if trace.names is not None:
            _check_text("names", trace.names.name, forbid="/\\ \t")
            width = len(trace.paths) if isinstance(trace, Bits) else trace.msb - trace.lsb + 1
            text = make_translation_filter(list(trace.names.values), datafmt="hex",
                                           size=width) + "\n"
            path = filter_path(savefile, trace.names)
            if out.setdefault(path, text) != text:
                raise ValueError(f"names {trace.names.name!r}: two different value lists")
    return out


def render_gtkw(dumpfile: Path, groups: list[Group], window: Window | None = None,
                savefile: Path | None = None) -> str:
    """Return the text of a GTKWave save file showing ``groups`` of ``dumpfile``.

    The text depends only on the arguments and on the dump's header (no dates, no window state).
    ``[dumpfile]`` is written as given: a dump named on GTKWave's command line takes precedence,
    and GTKWave resolves a relative one from its working directory. ``savefile`` (default: the
    dump's name with .gtkw) places the translate filter files.
    """
    dumpfile = Path(dumpfile)
    savefile = Path(savefile) if savefile is not None else dumpfile.with_suffix(".gtkw")
    _check_text("dumpfile", str(dumpfile))
    declared = Dump.declared_of(dumpfile)
    out = io.StringIO()
    save = GTKWSave(out)
    save.comment("", "GTKWave save file written by gpf.rtl.gtkw", "")
    save.dumpfile(str(dumpfile), abspath=False)
    save.size(*WINDOW_SIZE)
    save.sst_expanded(False)
    save.signals_width(SIGNALS_WIDTH)
    if window is not None:
        save.timestart(max(window.start, 0))
        save.zoom_markers(window.zoom, -1 if window.marker is None else window.marker)
    for group in groups:
        _write_group(save, group, declared, dumpfile, savefile)
    return "\n".join(line.rstrip() for line in out.getvalue().splitlines()) + "\n"


def _traces(groups: list[Group | Trace | Bits]) -> list[Trace | Bits]:
    out: list[Trace | Bits] = []
    for item in groups:
        out += _traces(item.traces) if isinstance(item, Group) else [item]
    return out


def _write_group(save: GTKWSave, group: Group, declared: dict[str, Declared] | None,
                 dumpfile: Path, savefile: Path) -> None:
    _check_text("group name", group.name)
    with save.group(group.name, closed=group.closed):
        for item in group.traces:
            if isinstance(item, Group):
                _write_group(save, item, declared, dumpfile, savefile)
            elif isinstance(item, Bits):
                _write_bits(save, item, declared, dumpfile, savefile)
            else:
                _write_trace(save, item, declared, dumpfile, savefile)


def _write_trace(save: GTKWSave, trace: Trace, declared: dict[str, Declared] | None,
                 dumpfile: Path, savefile: Path) -> None:
    datafmt, extra = _trace_format(trace)
    if extra & GTKWFlag.fpdecshift:
        # not in GTKWSave: the shift GTKWave applies to the following fpdecshift traces
        save.file.write(f"[fpshift_count] {trace.frac_bits}\n")
    alias = None
    if trace.label is not None:
        _check_text("label", trace.label, forbid="{}")
        alias = trace.label.replace(".", LABEL_DOT)
    names = str(filter_path(savefile, trace.names)) if trace.names is not None else None
    base, parent, bits = _trace_signals(trace, declared, dumpfile)
    if names is not None and bits is None and parent != base:
        # GTKWave 3.3.118 shows a signal the FST declares an enum (Verilator's ctrl state_t)
        # through the FST's table only, never through a filter file; a vector combined from
        # the signal's bits takes the file
        bits = list(range(trace.msb - trace.lsb + 1))
    if bits is None or len(bits) == 1:  # a whole signal, or one bit: a logic waveform
        save.trace(parent if bits is None else f"({bits[0]}){parent}", alias=alias,
                   datafmt=datafmt, extraflags=extra, translate_filter_file=names)
    else:  # a bit slice: the bits combined into one vector
        save.trace_combined(f"{base}[{trace.msb}:{trace.lsb}]", [(k, parent) for k in bits],
                            alias=alias, datafmt=datafmt, extraflags=extra,
                            translate_filter_file=names)


def _write_bits(save: GTKWSave, bits: Bits, declared: dict[str, Declared] | None,
                dumpfile: Path, savefile: Path) -> None:
    _check_text("label", bits.label, forbid="{}")
    if not bits.paths:
        raise ValueError(f"{bits.label}: no signals to combine")
    for path in bits.paths:
        _check_text("path", path, forbid="{} \t[]")
        if declared is not None and path not in declared:
            raise ValueError(f"{path}: no such signal in {dumpfile}")
        if declared is not None and declared[path] is not None:
            raise ValueError(f"{path}: not a 1-bit signal")
    names = str(filter_path(savefile, bits.names)) if bits.names is not None else None
    # the label is the combined vector's own name (GTKWave shows it as it shows an alias)
    save.trace_combined(bits.label.replace(".", LABEL_DOT), list(bits.paths), datafmt="hex",
                        translate_filter_file=names)


def _trace_format(trace: Trace) -> tuple[str, GTKWFlag]:
    """GTKWSave's datafmt and extra flags: hex, (un)signed decimal, or fixed point."""
    if trace.names is not None or trace.frac_bits is None:
        return "hex", GTKWFlag.none
    width = trace.msb - trace.lsb + 1
    if not 0 <= trace.frac_bits < MAX_DECIMAL_WIDTH:
        raise ValueError(f"{trace.path}: frac_bits {trace.frac_bits} not in 0..63")
    if width > MAX_DECIMAL_WIDTH:
        raise ValueError(
            f"{trace.path}[{trace.msb}:{trace.lsb}]: GTKWave shows vectors wider than "
            f"{MAX_DECIMAL_WIDTH} bits in hex only"
        )
    datafmt = "signed" if trace.signed else "dec"
    return datafmt, GTKWFlag.fpdecshift if trace.frac_bits else GTKWFlag.none


def _trace_signals(trace: Trace, declared: dict[str, Declared] | None, dumpfile: Path
                   ) -> tuple[str, str, list[int] | None]:
    """The signal's name without range, GTKWave's name of it and, for a part of it, the bits (k
    counted from the declared msb, most significant first); None for the whole signal."""
    if trace.msb < trace.lsb or trace.lsb < 0:
        raise ValueError(f"{trace.path}: range [{trace.msb}:{trace.lsb}] must have msb >= lsb >= 0")
    _check_text("path", trace.path, forbid="{} \t")
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
        return base, base, None
    dmsb, dlsb = decl
    parent = f"{base}[{dmsb}:{dlsb}]"
    if (trace.msb, trace.lsb) == (dmsb, dlsb):
        return base, parent, None
    lo, hi = min(dmsb, dlsb), max(dmsb, dlsb)
    if not (lo <= trace.lsb and trace.msb <= hi):
        raise ValueError(f"{base}[{trace.msb}:{trace.lsb}] is outside {parent}")
    return base, parent, [abs(dmsb - b) for b in range(trace.msb, trace.lsb - 1, -1)]


def _check_text(what: str, text: str, forbid: str = "") -> None:
    bad = set(text) & set(forbid + "\n\r")
    if not text or bad:
        raise ValueError(f"{what} {text!r}: must be non-empty, without {sorted(bad)}")


# --- the dump, through pywellen -------------------------------------------------------------


class Dump:
    """An FST or VCD file's variables, by the names GTKWave gives them, and their values."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        with self._unreadable():
            wave = pywellen.Waveform(str(self.path))
            self._vars = {_gtkwave_name(v): v for v in wave.all_vars()}

    @contextmanager
    def _unreadable(self) -> Iterator[None]:
        """pywellen's errors as ValueError: a RuntimeError for a file it cannot read, a Rust
        panic (pyo3's PanicException, a BaseException) for a damaged or unfinished one."""
        try:
            yield
        except BaseException as exc:
            if not isinstance(exc, Exception) and type(exc).__name__ != "PanicException":
                raise
            raise ValueError(f"{self.path}: not a readable FST or VCD ({exc})") from exc

    def declared(self) -> dict[str, Declared]:
        """Each signal's declared range: [width-1:0] (pywellen gives no other), None for 1 bit."""
        return {name: (v.bitwidth - 1, 0) if v.bitwidth > 1 else None
                for name, v in self._vars.items()}

    @classmethod
    def declared_of(cls, path: Path) -> dict[str, Declared] | None:
        """``declared()`` of the dump at ``path``; None when there is none, or when it cannot be
        read (then a warning says why)."""
        if not Path(path).exists():
            return None
        try:
            return cls(path).declared()
        except ValueError as exc:
            warnings.warn(f"{exc}: declared ranges not read; bit slices need the range in "
                          "the path", stacklevel=3)
            return None

    def __contains__(self, name: str) -> bool:
        return name in self._vars

    def changes(self, name: str) -> list[tuple[int, int | None]]:
        """(time, value) of each change of a signal (value None where not 0/1 bits)."""
        out = []
        var = self._vars[name]
        with self._unreadable():
            signal = var.signal
            for i in range(len(signal)):
                time, value = signal[i]
                out.append((time, value if isinstance(value, int) else None))
        return out

    def all_high(self, *names: str) -> list[int]:
        """The times at which the 1-bit signals ``names`` become all 1 together."""
        events = sorted((t, i, v) for i, n in enumerate(names) for t, v in self.changes(n))
        now = [0] * len(names)
        out: list[int] = []
        high = False
        for k, (time, i, value) in enumerate(events):
            now[i] = value or 0
            if k + 1 < len(events) and events[k + 1][0] == time:
                continue  # every change at this time first
            if all(now) and not high:
                out.append(time)
            high = all(now)
        return out


def _gtkwave_name(var: pywellen.Var) -> str:
    """pywellen's full name, with an array element's name completed: Verilator puts ``a[3]`` of
    an unpacked array ``a`` in a scope ``a``, which pywellen names ``a.[3]`` and GTKWave
    ``a.a[3]``."""
    name = var.full_name
    if var.name.startswith("["):
        scope = name[: -len(var.name) - 1]
        name = f"{scope}.{scope.rpartition('.')[2]}{var.name}"
    return name.replace(" ", "")
