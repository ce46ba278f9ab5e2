"""Every block's testbench on both simulators, two configs, one and two lanes; waves; mutants.

Each run generates the RTL, builds it in build/<config>/<sim>/<module> and runs every cocotb
test of tb/<module>/test_<module>.py (bit-exact scoreboard, stalls, latency, corrupted model).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from gpf.config import load_config
from gpf.rtl.generate import MODULES as BLOCKS
from gpf.rtl.generate import TEMPLATE_DIR
from gpf.sim import run_sim
from gpf.toolchain import LZ4_HEADER, icarus_missing

pytestmark = [pytest.mark.sim, pytest.mark.slow]

SIM_MARKS = {"verilator": (), "icarus": pytest.mark.skipif(icarus_missing() is not None,
                                                           reason=icarus_missing() or "")}


def waves_possible(sim: str) -> bool:
    return sim == "icarus" or LZ4_HEADER.exists()


APP_CONFIGS = {"bot": ("bot", "odd"), "uav": ("uav", "uav_seed002")}  # default, odd words


# blocks of both applications whose uav RTL has parts of its own (a 7-state mean and Sigma, the
# quaternion's norm, the covariance's two blocks): they run uav too; the other blocks of both
# (grng, exp, sqrt, recip, cordic_atan2) differ between the applications in word widths only
APP_SPECIFIC = {"sample_cond", "moments", "cholesky", "sigma_predict"}

# blocks whose uav RTL has an ecp5 shape that odd (bot's words, ecp5) does not reach: the uav
# configs are xc7, so these also run uav in its ecp5 shape
UAV_ECP5_RUNS = {"propagate_uav", "weight_uav", "moments"}

# the serial blocks, whose runs outlast their builds, build at -O1; the others at -O0, where the
# build costs more than the slower run (gpf.sim.VERILATOR_OPT)
RUN_BOUND = {"cholesky", "sigma_predict"}


def block_matrix(name: str) -> tuple[list, list]:
    """A block's (sim, config, lanes) runs: those of `make test` and the rest of the matrix
    (`make regress`). `make test`: Verilator runs the application's default config at LANES 1
    with every beat and waves, Icarus its odd config (odd words; bot's: ecp5, N = 1020) at
    LANES 2 with waves, every directed test and a fiftieth of the random beats (TEST_LEVEL=quick:
    Icarus is there for a second simulator's semantics, Verilator for the volume); a block of
    both applications with uav-only RTL runs uav at LANES 2 on Verilator, and uav's ecp5 shape,
    where odd does not reach it, runs on Verilator (both with a fifth of the beats:
    TEST_LEVEL=short). So every block runs on both
    simulators (with waves), at both LANES, with odd words, in each application where its RTL
    differs. `make regress`: the rest of the matrix (the default config at LANES 2, the odd one
    at 1, the odd one on Verilator, the default on Icarus, uav on every block of both
    applications; Icarus with a fifth of the beats) and every beat of the runs make test
    shortens on Verilator."""
    block = BLOCKS[name]
    default, odd = APP_CONFIGS[block.apps[0]]
    two = 2 if block.laned else 1
    quick = [("verilator", default, 1)]
    if len(block.apps) > 1 and name in APP_SPECIFIC:
        quick.append(("verilator", "uav", two))
    if name in UAV_ECP5_RUNS:
        quick.append(("verilator", "uav-familyecp5", 1))
    quick.append(("icarus", odd, two))
    rest = [("verilator", default, 2), ("verilator", odd, 2), ("verilator", odd, 1),
            ("icarus", default, 1)]
    if len(block.apps) > 1:
        rest += [("verilator", "uav", 2), ("icarus", "uav_seed002", 2)]
    if not block.laned:   # the same RTL at any LANES: LANES 1 only
        rest = [(sim, config, 1) for sim, config, _ in rest]
    rest = [r for i, r in enumerate(rest) if r not in quick and r not in rest[:i]]
    return quick, rest


def block_runs() -> list:
    """(module, sim, config, lanes, level) for every block (block_matrix): `make test`'s runs,
    then `make regress`'s, where the runs make test shortens run again with every beat."""
    runs = []
    for name, block in BLOCKS.items():
        if block.is_filter:   # the whole filters: tests/test_sim_filter.py
            continue
        quick, rest = block_matrix(name)
        for run in quick + rest:
            sim, config, lanes = run
            marks = [SIM_MARKS[sim]] if SIM_MARKS[sim] else []
            ident = f"{name}-{config}-lanes{lanes}-{sim}"
            if run in quick and sim == "verilator" and run != quick[0]:
                runs.append(pytest.param(name, *run, "short", marks=marks, id=f"{ident}-short"))
            regress = run in rest or sim == "verilator" and run != quick[0]
            level = "default" if sim == "verilator" else "short" if regress else "quick"
            runs.append(pytest.param(name, *run, level, id=ident,
                                     marks=[*marks, pytest.mark.regress] if regress else marks))
    return runs


@pytest.mark.parametrize("module,sim,config,lanes,level", block_runs())
def test_block(module: str, sim: str, config: str, lanes: int, level: str) -> None:
    name, _, family = config.partition("-family")
    cfg = load_config(f"configs/{name}.toml",
                      {"filter.lanes": lanes, **({"filter.family": family} if family else {})})
    quick, _ = block_matrix(module)
    # waves: make test's run of the default config on Verilator and its run on Icarus
    waves = (sim, config, lanes) in (quick[0], quick[-1]) and waves_possible(sim)
    level = os.environ.get("TEST_LEVEL") or level
    result = run_sim(cfg, module, sim, waves=waves, seed=1000 + lanes,
                     log_file=Path("build") / cfg.name / f"{module}-{sim}.log",
                     verilator_opt="-O1" if module in RUN_BOUND else "-O0",
                     extra_env={"TEST_LEVEL": level})
    assert result.passed, f"{result.failed}/{result.tests} failed: see {result.results_xml}"
    assert result.tests >= 6
    if waves:
        assert result.waves is not None and result.waves.stat().st_size > 0
        assert result.waves.with_suffix(".gtkw").exists()


# (module, template, text, replacement): one operator or constant changed in each
MUTANTS = {
    "grng-lfsr-xor": ("grng", "grng_lfsr258.sv.j2", "uniform_d = uniform_d ^ step[c];",
                 "uniform_d = uniform_d | step[c];"),
    "grng-horner-add": ("grng", "grng_icdf.sv.j2", "+ {{ sext(\"$signed({c0_4a_q",
                        "- {{ sext(\"$signed({c0_4a_q"),
    # c2 x truncated, not rounded half up
    "grng-rounding": ("grng", "grng_icdf.sv.j2", "{c1_3a_q, 1'b1,", "{c1_3a_q, 1'b0,"),
    "grng-backpressure": ("grng", "grng.sv.j2", "assign take = m_axis_tvalid && m_axis_tready;",
                          "assign take = m_axis_tvalid;"),
    # half the FIFO: steady flow still at full rate, a restart after a stall not
    "grng-fifo-depth": ("grng", "grng.sv.j2", "localparam int FIFO_LOG2 = {{ fifo_log2 }};",
                        "localparam int FIFO_LOG2 = {{ fifo_log2 - 1 }};"),
    # a lane's copy of the sources' enable wrong while a seed loads (checked against run_d)
    "grng-lane-run": ("grng", "grng.sv.j2", "(s_seed_tvalid ? last_l_q : first_l_q)",
                      "first_l_q"),
    "grng-credit": ("grng", "grng.sv.j2", "held_q <= (FIFO_LOG2+1)'($unsigned(DEPTH - 4))",
                    "held_q <= (FIFO_LOG2+1)'($unsigned(DEPTH - 1))"),
    "exp-interp-round": ("exp", "exp_lane.sv.j2", "(SW+RB+1)'(1 <<< (RB-1))",
                         "(SW+RB+1)'(1 <<< RB)"),
    "exp-underflow": ("exp", "exp_lane.sv.j2", "z5_q <= s4 > (NW+1)'($unsigned(MW));",
                      "z5_q <= s4 >= (NW+1)'($unsigned(MW));"),
    "exp-last": ("exp", "exp.sv.j2", "assign m_axis_tlast = last_q[LATENCY-1];",
                 "assign m_axis_tlast = last_q[LATENCY-2];"),
    "sqrt-digit-compare": ("sqrt", "sqrt_lane.sv.j2", "assign ge{{ k }} = p{{ k }} >= t{{ k }};",
                           "assign ge{{ k }} = p{{ k }} > t{{ k }};"),
    "recip-rounding": ("recip", "recip_lane.sv.j2",
                       "assign sum = {1'b0, quo_q} + {{ out_width + 1 }}'(rb_q);",
                       "assign sum = {1'b0, quo_q} + {{ out_width + 1 }}'(1'b0);"),
    # the last iteration only: its wrong turn moves the angle by 2 ANGLE[N-1], about 0.6 LSB
    "cordic-direction": ("cordic_atan2", "cordic_atan2_lane.sv.j2",
                         "assign up{{ i }} = y{{ i }}_q >= 0;",
                         "assign up{{ i }} = {{ '!' if loop.last else '' }}(y{{ i }}_q >= 0);"),
    "cordic-prerotation": ("cordic_atan2", "cordic_atan2_lane.sv.j2",
                           "(y[IW-1] ? MINUS_QUARTER : QUARTER)",
                           "(y[IW-1] ? QUARTER : MINUS_QUARTER)"),
    # q'2's last Omega term (+h0 q3 from the model's table) subtracted instead
    "propagate_uav-omega-sign": ("propagate_uav", "propagate_uav_lane.sv.j2",
                                 "('~' if t.neg else '')",
                                 "('~' if t.neg != (r.base == 'y2' and loop.last) else '')"),
    "propagate_uav-rounding": ("propagate_uav", "propagate_uav_lane.sv.j2",
                               "'sd{{ r.half }}", "'sd{{ r.half // 2 }}"),
    # every beat takes the operands held from the previous step's first beat
    "propagate_uav-operands": ("propagate_uav", "propagate_uav.sv.j2",
                               "assign op_beat = first_q ? op : op_hold_q;",
                               "assign op_beat = op_hold_q;"),
    # operands sampled with the first beat after reset only: later steps use stale mu and L
    "sample_cond-first-of-step": ("sample_cond", "sample_cond.sv.j2",
                                  "first_q <= s_axis_tlast;", "first_q <= 1'b0;"),
    # half an LSB minus one: only exact ties round differently (the corner test makes them)
    "sample_cond-round-half": ("sample_cond", "sample_cond_lane.sv.j2",
                               "o.low_bits ~ \"'d\" ~ o.low ~",
                               "o.low_bits ~ \"'d\" ~ (o.low - 1) ~"),
    "sample_cond-sat-any": ("sample_cond", "sample_cond_lane.sv.j2",
                            "{% if not loop.last %} || {% endif %}",
                            "{% if not loop.last %} && {% endif %}"),
    # T for a in p' = p + T v + a e (a and b share their raw value: a = b dt / 2, dt = 1)
    "propagate_bot-gain": ("propagate_bot", "propagate_bot_lane.sv.j2",
                           "'(e{{ axis }}) * {{ ew + consts.a.width }}'(C_A);",
                           "'(e{{ axis }}) * {{ ew + consts.a.width }}'(C_T);"),
    "propagate_bot-sat-vy": ("propagate_bot", "propagate_bot_lane.sv.j2",
                             "sat_q <= pn0_ovf || vn0_ovf || pn1_ovf || vn1_ovf;",
                             "sat_q <= pn0_ovf || vn0_ovf || pn1_ovf;"),
    "moments-reference": ("moments", "moments.sv.j2",
                          "{{ W + 1 }}'(x1_{{ l }}_{{ i }}_q) - {{ W + 1 }}'(ref{{ i }}_q);",
                          "{{ W + 1 }}'(x1_{{ l }}_{{ i }}_q) + {{ W + 1 }}'(ref{{ i }}_q);"),
    # the mean floored instead of rounded half up
    "moments-mean-rounding": ("moments", "moments.sv.j2",
                              "\"$signed({ref%d_q, 1'b1})\"", "\"$signed({ref%d_q, 1'b0})\""),
    # the rescale of the sums floors: its rounding bit c = acc[S - 1] never added
    "moments-rescale-rounding": ("moments", "moments.sv.j2",
                                 "{{ w }}'({{ name }}_cin);", "{{ w }}'({{ name }}_cin & 1'b0);"),
    # an accumulator rescaled by its own beat's shift only, not the other's since its last beat
    "moments-shift-since": ("moments", "moments.sv.j2",
                            "{{ tw }}'({{ sp }}) + ", ""),
    # the flush's weight not cleared: it adds whatever the bus holds
    "moments-flush-weight": ("moments", "moments.sv.j2",
                             "w1_{{ l }}_q <= flush_q ? '0 : ", "w1_{{ l }}_q <= "),
    # a beat arriving on the wrong parity enters the loop at once (the other accumulator's slot)
    "moments-parity": ("moments", "moments.sv.j2",
                       "assign aligned = open_q || par_q == need_q;", "assign aligned = 1'b1;"),
    # Sigma's quotient floored instead of rounded half up (its half bit dropped)
    "moments-sigma-rounding": ("moments", "moments.sv.j2",
                               "{{ d.qb }}'(sig{{ q }}_quo[0])", "{{ d.qb }}'(1'b0)"),
    # the dividers' subtraction a unit short (no carry into p + ~d)
    "moments-divider-carry": ("moments", "moments_div.sv.j2",
                              "({p, 1'b1} + {dx, sub})", "({p, 1'b1} + {dx, 1'b0})"),
    # uav's quaternion norm: the root's digit 3 takes 3R + 1 for 3R' = 3 (4R + 3) = 12R + 9
    "moments-root-digit": ("moments", "moments.sv.j2",
                           "r3_q <= (r3i1 << 2) | {{ dg }}'d1;",
                           "r3_q <= (r3i_q << 2) | {{ dg }}'d1;"),
    # ecp5 with 20-bit words: w dx's part w_lo dx_hi one place too high in the exact w dx
    "moments-wdx-split": ("moments", "moments.sv.j2",
                          "(sext('wh3_%d_%d_q' % (l, i), W + 1, wdx_w), lo),",
                          "(sext('wh3_%d_%d_q' % (l, i), W + 1, wdx_w), lo + 1),"),
    # the rescale's rounding bit for a shift of 4 a taken one place low, acc[4 a - 2]
    "moments-round-bit": ("moments", "moments.sv.j2",
                          "2'b00} - 1'b1;", "2'b00} - 2'd2;"),
    # a clock without a beat shifts the accumulator in b_q by whatever the shift bus held
    "moments-idle-shift": ("moments", "moments.sv.j2",
                           "{{ name }}_s4_q <= {{ name }}_v3p_q && !{{ name }}_fd3p_q ?",
                           "{{ name }}_s4_q <= !{{ name }}_fd3p_q ?"),
    # m_i m_j (one multiplier, the pairs in turn) loaded into each pair's register a slot early
    "moments-pair-slot": ("moments", "moments.sv.j2",
                          "if (mms_q[{{ loop.index0 + mm_lat - 1 }}])",
                          "if (mms_q[{{ loop.index0 + mm_lat - 2 }}])"),
    # p = w dx truncated to P_BITS instead of rounded half up
    "moments-p-rounding": ("moments", "moments.sv.j2",
                           "{{ wdx_w }}'sd{{ 2 ** (k - 1) }};", "{{ wdx_w }}'sd0;"),
    # uav on xc7: a quaternion component's square with its top bits' part one place too high
    "moments-quaternion-square": ("moments", "moments.sv.j2",
                                  "W + hb, 2 * W) }} <<< 17)", "W + hb, 2 * W) }} <<< 18)"),
    # a step counted as beyond reach whatever its shifts
    "moments-reach": ("moments", "moments.sv.j2", "|| sh5_q != '0;", "|| 1'b0;"),
    # absolute weights 2^-t: the running minimum not subtracted
    "weight-absolute": ("weight_uav", "_weight.sv.j2",
                        "{lower ? trel{{ lane }}_m : trel{{ lane }}_r, lane_t",
                        "{lane_t[{{ lane }}][TW-1:TF], lane_t"),
    # the running minimum carried over from the previous step
    "weight-min-per-step": ("weight_bot", "_weight.sv.j2",
                            "assign r_prev = mfirst_q ? TOP : r_q;", "assign r_prev = r_q;"),
    # an entry's overflow never detected: it wraps (the corners saturate)
    "sigma_predict-saturation": ("sigma_predict", "sigma_predict.sv.j2",
                                 "assign o{{ loop.index0 }} = !c_fits_q",
                                 "assign o{{ loop.index0 }} = 1'b0 && !c_fits_q"),
    # every term's partial sum written to its entry, the last entry's first one marks it done
    "sigma_predict-entry-write": ("sigma_predict", "sigma_predict.sv.j2",
                                  "b_on_q && b_final_q && b_dest_q ==", "b_on_q && b_dest_q =="),
    "sigma_predict-first-term": ("sigma_predict", "sigma_predict.sv.j2",
                                 "({{ pre }}first_q ? {{ pre }}init_q : acc_q)", "(acc_q)"),
    # z meets the CORDIC's angle one beat early: a step's first beat gets the last step's z
    "weight-bot-z-delay": ("weight_bot", "weight_bot.sv.j2", ".z      (zd_q[ZD*AW-1 -: AW]),",
                           ".z      (zd_q[(ZD-1)*AW-1 -: AW]),"),
    "weight-bot-x-delay": ("weight_bot", "weight_bot_lane.sv.j2",
                           "assign x_out = xd_q[LAT*XW-1 -: XW];",
                           "assign x_out = xd_q[(LAT-1)*XW-1 -: XW];"),
    "weight-uav-whiten-round": ("weight_uav", "_weight.sv.j2", "PW'(1 <<< (S1-1))",
                                "PW'(1 <<< S1)"),
    # only the negative overflow flagged (the saturated value's sign is not observable: w = 0)
    "weight-uav-sat-flag": ("weight_uav", "_weight.sv.j2",
                            "{{ name }}_full[W] != {{ name }}_full[W-1];",
                            "{{ name }}_full[W] && !{{ name }}_full[W-1];"),
    "cholesky-floor-compare": ("cholesky", "cholesky_core.sv.j2",
                               "assign floored = pvd_q < floor_q;",
                               "assign floored = pvd_q <= floor_q;"),
    # the next pivot's L_j+1,j^2 with its cross term 2 aH aL 2^17 counted once
    "cholesky-pivot-square": ("cholesky", "cholesky_core.sv.j2",
                              "<<< {{ lo + 1 }});", "<<< {{ lo }});"),
    # 2 num + L_jj's high part not carried into from its low W + 1 bits
    "cholesky-dnum-carry": ("cholesky", "cholesky_core.sv.j2",
                            "dlo[{{ r }}][W+1] ? mh1_q[{{ r }}] : mh0_q[{{ r }}]",
                            "mh0_q[{{ r }}]"),
    "cholesky-quotient-sign": ("cholesky", "cholesky_core.sv.j2",
                               "(neg_q[{{ r }}] ? ~qv[{{ r }}] : qv[{{ r }}])",
                               "(neg_q[{{ r }}] ? -qv[{{ r }}] : qv[{{ r }}])"),
    # M's bits above the divider's remainder dropped from the saturation test (M >= L_jj 2^W,
    # compared as {mtop_q, rem_q, mlo_q}: the load's registers hold M's low QB + DW bits)
    "cholesky-sat-overflow": ("cholesky", "cholesky_core.sv.j2",
                              "mtop_q[r] <= {{ mt }}'(mag[r] >> (QB + {{ dw }}));",
                              "mtop_q[r] <= '0;"),
    # the root's remainder not cleared between columns (its clear is a synchronous reset)
    "cholesky-root-clear": ("cholesky", "cholesky_core.sv.j2",
                            "if (rst || (busy_q && !done_q && ph_rad_q)) begin",
                            "if (rst) begin"),
    # column 0's L entries written in every column (the column one-hot's bit not read)
    "cholesky-column-write": ("cholesky", "cholesky_core.sv.j2",
                              "          if (col_q[{{ b }}]) begin", "          if (1'b1) begin"),
    # a dot product's term with the wrong weight: the four-part shape's aL bH a bit too high
    "cholesky-dot-term": ("cholesky", "cholesky_core.sv.j2",
                          "lh_q[\" ~ k ~ \"]\", w + 1, acc_w) }} <<< LO;",
                          "lh_q[\" ~ k ~ \"]\", w + 1, acc_w) }} <<< (LO + 1);"),
    # the dot product's first product added where it is subtracted (the tree's S_aj node)
    "cholesky-dot-sub": ("cholesky", "cholesky_core.sv.j2", '{{ "-" if t == 0 else "+" }}',
                         '{{ "-" if t == 0 and v > 1 else "+" }}'),
    # the same two on the xc7 shape (a product as a bL + a bH 2^LO): the pivot's a aH a LSB
    # too high, a dot product's a bH a bit too low
    "cholesky-pivot-square-xc7": ("cholesky", "cholesky_core.sv.j2",
                                  "sbh_q\", 2 * w - lo, acc_w) }} <<< LO;",
                                  "sbh_q\", 2 * w - lo, acc_w) }} <<< (LO + 1);"),
    "cholesky-dot-term-xc7": ("cholesky", "cholesky_core.sv.j2",
                              "pbh_q[\" ~ k ~ \"]\", 2 * w - lo, acc_w) }} <<< LO;",
                              "pbh_q[\" ~ k ~ \"]\", 2 * w - lo, acc_w) }} <<< (LO - 1);"),
    # AXI4-Stream protocol (tb/stream.py's checks): tdata or tlast different only while a beat
    # is offered and not taken, right again at the handshake, so every value checked is right
    "cholesky-stall-data": ("cholesky", "cholesky.sv.j2", "assign m_axis_tdata = m_data_q;",
                            "assign m_axis_tdata = m_data_q ^ {{ out_width }}'(m_axis_tvalid "
                            "&& !m_axis_tready);"),
    "cholesky-stall-last": ("cholesky", "cholesky.sv.j2", "assign m_axis_tlast = m_last_q;",
                            "assign m_axis_tlast = m_last_q ^ (m_axis_tvalid "
                            "&& !m_axis_tready);"),
    # a line-rate block's output buffer: the read pointer does not move on a pop, so the bus
    # shows one word twice and skips the next
    "outbuf-read-pointer": ("sample_cond", "gpf_outbuf.sv.j2", "rd_q <= rd_q ^ pop;",
                            "rd_q <= rd_q;"),
    # the GRNG's FIFO shows a sample's LSB flipped until it is popped (StreamMonitor's checks)
    "grng-stall-data": ("grng", "gpf_fifo.sv.j2", "assign pop_data = mem[rd_q];",
                        "assign pop_data = mem[rd_q] ^ WIDTH'(!pop);"),
}


# mutants that only a config other than the module's first application's catches: the
# 18 x 18 parts are the ecp5 shape (odd), bot's is xc7's
MUTANT_CONFIG: dict[str, str] = {"cholesky-pivot-square": "odd", "cholesky-dot-term": "odd",
                                 "moments-quaternion-square": "uav", "moments-root-digit": "uav",
                                 "moments-wdx-split": "odd"}


def run_mutant(mutant: str, *args, log_file: Path, **kwargs):
    """run_sim on a mutant's RTL; None when a simulation-only check of the RTL stopped the
    simulator ($fatal): caught, if its log says so (a mutant that does not build must not count)."""
    try:
        return run_sim(*args, log_file=log_file, **kwargs)
    except RuntimeError:
        assert "FATAL" in log_file.read_text(), f"mutant {mutant} did not run"
        return None


def mutated_templates(tmp_path: Path, mutant: str, template: str, old: str, new: str) -> Path:
    """A copy of the templates with `old` replaced by `new` (once) in `template`."""
    templates = tmp_path / "templates"
    shutil.copytree(TEMPLATE_DIR, templates)
    path = templates / template
    text = path.read_text()
    assert text.count(old) == 1, f"mutant {mutant}: '{old}' not found once in {template}"
    path.write_text(text.replace(old, new))
    return templates


# make regress only: the mutants added as the RTL was pipelined beyond each block's first ones
# (its arithmetic, its rounding, its flow under stalls: those stay in make test, a new mutant
# too unless listed here); `make mutants` scores every operator and constant besides
MUTANTS_IN_REGRESS = (
    "grng-fifo-depth", "grng-lane-run",
    "moments-rescale-rounding", "moments-shift-since", "moments-flush-weight", "moments-parity",
    "moments-sigma-rounding", "moments-divider-carry", "moments-root-digit", "moments-wdx-split",
    "moments-round-bit", "moments-idle-shift", "moments-pair-slot", "moments-p-rounding",
    "moments-quaternion-square", "moments-reach",
    "weight-absolute", "weight-min-per-step",
    "sigma_predict-saturation", "sigma_predict-entry-write",
    "cholesky-pivot-square", "cholesky-dnum-carry", "cholesky-quotient-sign", "cholesky-dot-term",
    "cholesky-dot-sub", "cholesky-pivot-square-xc7", "cholesky-dot-term-xc7",
    "cholesky-stall-last", "cholesky-sat-overflow", "cholesky-root-clear", "cholesky-column-write",
)


def mutant_params(mutants: dict, in_regress: tuple[str, ...]) -> list:
    """The mutants as test parameters, those in `in_regress` marked for make regress only."""
    unknown = set(in_regress) - set(mutants)
    assert not unknown, f"no such mutants: {sorted(unknown)}"
    return [pytest.param(m, marks=[pytest.mark.regress] if m in in_regress else [])
            for m in mutants]


@pytest.mark.skipif(icarus_missing() is not None, reason=icarus_missing() or "")
@pytest.mark.parametrize("mutant", mutant_params(MUTANTS, MUTANTS_IN_REGRESS))
def test_mutated_template_fails(tmp_path: Path, mutant: str) -> None:
    module, template, old, new = MUTANTS[mutant]
    templates = mutated_templates(tmp_path, mutant, template, old, new)
    # the module's application, or the config where the mutant is not equivalent
    config = MUTANT_CONFIG.get(mutant, "bot" if "bot" in BLOCKS[module].apps else "uav")
    # TEST_LEVEL=quick (a fiftieth of the random beats): each mutant was seen to fail at the
    # short and default levels too
    result = run_mutant(mutant, load_config(f"configs/{config}.toml"), module, "icarus", seed=1,
                        template_dir=templates, build_root=tmp_path / "build",
                        log_file=tmp_path / "sim.log", all_modules=False,
                        extra_env={"TEST_LEVEL": "quick", "GPF_FAIL_FAST": "1"})
    if result is None:
        return
    assert result.tests > 0
    assert result.failed > 0, f"mutant {mutant} survived the {module} testbench"
