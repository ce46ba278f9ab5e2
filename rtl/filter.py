"""The whole filter's top and controller: their widths, from the blocks' own contexts.

The top only wires blocks: every field it moves is sized by the block that makes it, and the
checks here fail generation if two blocks disagree about a stream between them.
"""

from __future__ import annotations

from typing import Any

from gpf.config import Config
from gpf.model.formats import SHIFT_BITS, datapath
from gpf.model.grng import COMPONENTS

CYCLES_W = 32          # the step's cycle count in the output beat
FIFO_DEPTH_LOG2 = 4    # process draws waiting beside sample_cond (its pipeline 8, its output 2, 1)
OUTBUF_BEATS = 2       # a line-rate block's output buffer (gpf_outbuf) holds up to two beats
EXAMPLE_CLOCK_MHZ = 125   # the example top's clock constraint: SPEC 9's bar
STEP_FIELDS = {"bot": ["z", "ox", "oy"],
               "uav": ["omega0", "omega1", "omega2", "accel0", "accel1", "accel2",
                       "v0", "v1", "v2"]}


def filter_context(cfg: Config) -> dict[str, Any]:
    from gpf.rtl.generate import MODULES, grng_context

    dp = datapath(cfg)
    app, n, word, lanes = dp.app, dp.n, dp.word, cfg.lanes
    ctx = {name: MODULES[name].context(cfg)
           for name in ("sample_cond", f"propagate_{app}", f"weight_{app}", "moments",
                        "cholesky", "sigma_predict")}
    sc, prop, wt, mom, chol, pred = (ctx[k] for k in (
        "sample_cond", f"propagate_{app}", f"weight_{app}", "moments", "cholesky",
        "sigma_predict"))
    draws = dp.draws()
    mu_w = n * word
    l_w = sum(dp.chol[i].width for i in range(n) for _ in range(i + 1))
    sig_w = chol["in_width"]
    pe_w = (draws - n) * dp.noise.width
    prop_op_w = prop.get("op_width", 0)
    weight_op_w = 3 * word
    cond_lane_w = sc["out_width"]
    prop_lane_w = mu_w + 1
    part_lane_w = mu_w + dp.weight.width + 1
    # the streams between blocks must agree
    checks = {
        "sample_cond op = {L, mu}": sc["op_width"] == mu_w + l_w,
        "sample_cond x = the state": sc["x_width"] == mu_w,
        "propagate in = {draws, x}": prop["in_width"] == mu_w + pe_w,
        "propagate out = {sat, x}": prop["out_width"] == prop_lane_w,
        "weight out = {shift, lanes {sat, w, x}}": wt["out_width"] == lanes * part_lane_w
        + SHIFT_BITS,
        "moments in = {shift, lanes {w, x}}": mom["in_w"] == lanes * (part_lane_w - 1)
        + SHIFT_BITS,
        "moments out = {ESS, flags, Sigma, mu}": mom["out_w"] == mu_w + sig_w + 3
        + dp.ess.width,
        "cholesky out = {flags, L}": chol["out_width"] == l_w + 3,
        "sigma_predict = {flags, Sigma}": pred["in_width"] == sig_w
        and pred["out_width"] == sig_w + 3,
        "FIFO covers sample_cond": sc["lane_latency"] + OUTBUF_BEATS + 1
        <= 1 << FIFO_DEPTH_LOG2,
    }
    broken = [name for name, ok in checks.items() if not ok]
    if broken:
        raise ValueError(f"gpf_{app}: blocks disagree: {', '.join(broken)}")
    npairs = len(mom["pairs"])
    pw = cfg.particles.bit_length()
    grng = grng_context(cfg, lanes=draws * lanes)
    return {
        "app": app, "lanes": lanes, "n": n, "word": word, "particles": cfg.particles,
        "draws": draws, "noise_w": dp.noise.width, "pe_w": pe_w, "pw": pw,
        "mu_w": mu_w, "l_w": l_w, "sig_w": sig_w, "npairs": npairs, "ntri": n * (n + 1) // 2,
        "mom_w": mom["out_w"], "chol_w": chol["out_width"],
        "init_w": pw + mu_w + sig_w, "step_w": len(STEP_FIELDS[app]) * word,
        "step_fields": STEP_FIELDS[app], "prop_op_w": prop_op_w, "weight_op_w": weight_op_w,
        "est_w": mu_w + sig_w + l_w + 8 + CYCLES_W + dp.ess.width, "cycles_w": CYCLES_W,
        "ess_w": dp.ess.width, "ess_fmt": str(dp.ess), "ess_shift": dp.ess_shift,
        "ess_frac": dp.ess.frac_bits, "shift_w": SHIFT_BITS,
        "part_w": lanes * part_lane_w + SHIFT_BITS,
        "cond_lane_w": cond_lane_w, "prop_lane_w": prop_lane_w, "part_lane_w": part_lane_w,
        "propagate": f"propagate_{app}", "weight": f"weight_{app}",
        "fifo_depth_log2": FIFO_DEPTH_LOG2,
        "grng_words": draws * lanes * COMPONENTS,
        "latency": None,
        "part_contexts": {"gpf_grng": grng},
    }


def axi_context(cfg: Config) -> dict[str, Any]:
    """gpf_<app>_axi: the core's widths, each stream's in whole bytes, the register block."""
    from gpf.rtl.regs import ADDR_W, regs_name

    ctx = filter_context(cfg)
    ctx["cond_w"] = ctx["lanes"] * ctx["cond_lane_w"]
    widths = {"init": ctx["init_w"], "step": ctx["step_w"], "est": ctx["est_w"],
              "cond": ctx["cond_w"], "part": ctx["part_w"]}
    return ctx | {f"{name}_bytes": -(-w // 8) for name, w in widths.items()} | {
        "regs": regs_name(ctx["app"]), "regs_aw": ADDR_W, "clock_mhz": EXAMPLE_CLOCK_MHZ,
        "part_contexts": {}}


HARNESS_STEPS_MAX = 1 << 14   # step beats the harness holds: longer runs take cocotb's drivers
HARNESS_DIR = "tb"            # beside the IP's files, outside every file list


def harness_context(cfg: Config) -> dict[str, Any]:
    """gpf_<app>_harness (simulation only): the core's stream widths, the stimulus depth and the
    clock it runs (tb/harness.py's CLOCK_NS of 10 ns)."""
    ctx = filter_context(cfg)
    return ctx | {"core": f"gpf_{ctx['app']}", "cond_w": ctx["lanes"] * ctx["cond_lane_w"],
                  "steps_max": HARNESS_STEPS_MAX, "half_period_ns": 5, "part_contexts": {}}
