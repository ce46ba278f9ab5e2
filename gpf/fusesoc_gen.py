#!/usr/bin/env python3
"""FuseSoC generator `gpf_rtl` (gpf.core): the generated SystemVerilog of one module as a core.

FuseSoC runs `python3 gpf/fusesoc_gen.py <input.yml>` in a folder of its own; this writes the
config's RTL into rtl/ there (as `gpf generate`) and a .core whose default target lists the
module's files, dependencies first. Parameters (gpf.core's `generate:` entries):

  config   the config file, relative to the calling core (gpf.core: configs/bot.toml)
  module   the module whose files the core lists (gpf_bot; `gpf list` names them all)
  gpf      optional: `gpf` arguments run as the core's pre_run hook in the build folder, with
           --config added after the subcommand, e.g. [run, --steps, 3, --json, run.json];
           its exit status is fusesoc's (gpf run and gpf sim: 1 when the RTL fails its test)
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

# gpf and yaml are imported only once _rerun_with_venv has found a python that has them
REPO = Path(__file__).resolve().parent.parent


def _rerun_with_venv() -> None:
    """FuseSoC takes the first python3 on PATH; when .venv is not active that one has no gpf:
    start again with the repository's .venv python (make venv)."""
    try:
        import gpf  # noqa: F401
    except ImportError:
        venv_python = REPO / ".venv" / "bin" / "python"
        if not venv_python.exists() or Path(sys.executable) == venv_python:
            sys.exit(f"gpf_rtl: {sys.executable} cannot import gpf: run `make venv` and "
                     "fusesoc from .venv (source .venv/bin/activate)")
        os.execv(venv_python, [str(venv_python), __file__, *sys.argv[1:]])


def core_text(vlnv: str, description: str, files: list[str], hook: list[str] | None) -> str:
    import yaml

    default: dict = {"filesets": ["rtl"]}
    core: dict = {
        "name": vlnv,
        "description": description,
        "filesets": {"rtl": {"file_type": "systemVerilogSource", "files": files}},
    }
    if hook:
        core["scripts"] = {"gpf": {"cmd": hook}}
        default["hooks"] = {"pre_run": ["gpf"]}
    core["targets"] = {"default": default}
    return "CAPI=2:\n" + yaml.safe_dump(core, sort_keys=False)


def main(input_file: str) -> int:
    import yaml

    from gpf.config import load_config
    from gpf.outputs import atomic_write_text
    from gpf.rtl.generate import generate

    spec = yaml.safe_load(Path(input_file).read_text())
    params = spec["parameters"]
    config = Path(spec["files_root"], params["config"])   # an absolute path stays as it is
    module = params["module"]
    try:
        cfg = load_config(config)
        # every module: generating a whole filter's alone would leave out its blocks' files
        generated = generate(cfg, Path("rtl").resolve())
    except (ValueError, ArithmeticError) as exc:   # a bad config (ConfigError is a ValueError)
        sys.exit(f"gpf_rtl: {exc}")
    if module not in generated.files:
        sys.exit(f"gpf_rtl: module {module!r} is not generated for config {cfg.name!r}: choose "
                 f"one of {', '.join(generated.files)}")
    files = [f"rtl/{p.name}" for p in generated.files[module]]   # relative to the .core
    hook = None
    if params.get("gpf"):
        # the python running this has gpf: the hook needs no PATH, and the config's path
        # is absolute because the hook runs in fusesoc's build folder
        command, *args = (str(a) for a in params["gpf"])
        hook = [sys.executable, "-m", "gpf.cli", command, "--config", str(config), *args]
    name = spec["vlnv"].split(":")[2]
    description = f"gpf generate --config {params['config']}: {module}"
    atomic_write_text(f"{name}.core", core_text(spec["vlnv"], description, files, hook))
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: fusesoc_gen.py GENERATOR_INPUT.yml (FuseSoC runs it: see gpf.core)")
    _rerun_with_venv()
    sys.exit(main(sys.argv[1]))
