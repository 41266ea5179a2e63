"""Regenerate the tables of the reference pages from the code, so the docs cannot drift from it.

    python docs/tools/gen_reference.py            # rewrite the generated blocks in docs/reference/*.md
    python docs/tools/gen_reference.py --check    # exit 1 naming the stale pages (docs/tools/build_docs.sh, tests/docs)
    python docs/tools/gen_reference.py --quick    # = --check (writes nothing)

A generated block sits between ``<!-- BEGIN generated: NAME -->`` and ``<!-- END generated: NAME -->`` in a page;
everything outside the markers is hand-written. Blocks: the estimator catalogue (roadload.estimators.CATALOG),
the chapter-5 settings, the vehicle presets, the tractive-force model registry, the simulator effects
(roadload.envs.EFFECTS), the sim-to-real candidate catalogue, the gym configuration fields (roadload.gym.config)
and the import-linter layers (pyproject.toml).
"""

from __future__ import annotations

import argparse
import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT / "docs" / "reference"

# the reference text's numbers for each part of a composition (Rhode 2018, chapter 3)
PART_REFERENCES = {
    ("psi", "l2"): "least squares",
    ("psi", "huber"): "Huber ψ (eq. 3.15-3.17)",
    ("robust_scale", True): "robust recursive scale (Alg. 3.3)",
    ("regularisation", "levenberg_marquardt"): "Levenberg-Marquardt, P(I + κP)⁻¹ (eq. 3.33-3.34, Alg. 3.4)",
    ("instruments", "delayed"): "instruments 𝔄_t = A_{t-k} (Alg. 3.9)",
    ("covariance", "kalman"): "Kalman Q/R (Alg. 3.13)",
    ("covariance", "stenlund_gustafsson"): "Stenlund-Gustafsson P_d (Alg. 3.16)",
}


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def table(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def estimator_catalog() -> str:
    from roadload.estimators import CATALOG
    from roadload.estimators.catalog import SPECIAL

    rows = []
    for name, entry in CATALOG.items():
        parts = ", ".join(f"{k}={v}" for k, v in entry.parts.items())
        refs = "; ".join(PART_REFERENCES[(k, v)] for k, v in entry.parts.items() if (k, v) in PART_REFERENCES)
        rows.append([f"`{name}`", entry.description, entry.algorithm, f"`{parts}`", refs])
    text = table(["name", "estimator", "Algorithm", "composition (make_config parts)", "parts in the text"], rows)
    return text + "\n\nAlso by name: " + ", ".join(f"`{s}`" for s in SPECIAL) + \
        " (own classes: RGTLS = Algorithm 3.8 with the noise covariance estimator, its lines 3-4 the kernel's " \
        "covariance stages on [A B], its own stages the generalised inverse iteration and eq. 3.43b; PKS = " \
        "Algorithm 3.21, the kernel with the polynomial shift as transition matrix)."


def chapter5() -> str:
    from roadload.estimators import chapter5_settings

    out = []
    for model in ("M3", "M4"):
        rows = [[f"`{name}`", ", ".join(f"{k}={v}" for k, v in s.items())]
                for name, s in chapter5_settings(model).items()]
        out.append(f"**{model}**\n\n" + table(["estimator", "settings (section 5.5)"], rows))
    return "\n\n".join(out)


def force_models() -> str:
    from roadload.estimators import get_model, model_names

    rows = []
    for name in model_names():
        m = get_model(name)
        rows.append([f"`{name}`", m.description,
                     ", ".join(f"{p} [{u}]" for p, u in zip(m.parameter_names, m.parameter_units)),
                     "white box" if m.white_box else "gray box"])
    return table(["model", "description", "parameters X [unit]", "kind"], rows)


def effects() -> str:
    from roadload.envs import EFFECTS

    out = []
    for name, e in EFFECTS.items():
        rows = []
        for pname, p in e.params.items():
            allowed = f"one of {list(p.choices)}" if p.choices else (
                f"[{p.lo:g}, {p.hi:g}]" if p.lo is not None and p.hi is not None else "")
            default = f"{p.default:g}" if isinstance(p.default, float) else str(p.default)
            rows.append([f"`{pname}`", default, p.unit, allowed, p.doc])
        out.append(f"### `{name}`\n\n{e.description}\n\n" + table(["parameter", "default", "unit", "range", "meaning"],
                                                                   rows))
    return "\n\n".join(out)


def presets() -> str:
    from roadload.presets import PRESETS, get_preset

    rows = []
    for name in PRESETS:
        spec = get_preset(name)
        rows.append([f"`{name}`", spec.description, f"{spec.body.mass:g}", spec.drivetrain.kind,
                     len(spec.drivetrain.gear_ratios)])
    return table(["preset", "vehicle", "mass [kg]", "drive-train", "gears"], rows)


def sim2real_candidates() -> str:
    from roadload.sim2real import candidate_names, get_candidate

    rows = []
    for name in candidate_names():
        c = get_candidate(name)
        rows.append([f"`{name}`", c.description, c.side, ", ".join(c.needs), c.sim_effect or "–"])
    return table(["candidate", "what it models", "side", "needs channels", "simulator switch"], rows)


def _config_rows(cls) -> list[list]:
    rows = []
    for name, f in cls.model_fields.items():
        if f.default_factory is not None:
            default = "(see below)" if hasattr(f.default_factory, "model_fields") else str(f.default_factory())
        else:
            default = repr(f.default)
        kind = getattr(f.annotation, "__name__", None) if not getattr(f.annotation, "__args__", None) else None
        kind = (kind or str(f.annotation).replace("typing.", "")).replace(" | ", " or ")
        rows.append([f"`{name}`", f"`{kind}`", f"`{default}`", f.description or ""])
    return rows


def gym_config() -> str:
    from roadload.gym.config import (EcoDriveConfig, EcoDriveReward, EcoHighwayConfig, EcoHighwayReward,
                                     EcoTrafficConfig, TrafficBehaviour, TrafficShield)

    out = []
    for title, cls in (("EcoDriveConfig", EcoDriveConfig), ("EcoDriveReward (`reward=`)", EcoDriveReward),
                       ("EcoHighwayConfig", EcoHighwayConfig), ("EcoHighwayReward (`reward=`)", EcoHighwayReward),
                       ("EcoTrafficConfig", EcoTrafficConfig), ("TrafficBehaviour (`traffic=`)", TrafficBehaviour),
                       ("TrafficShield (`shield=`)", TrafficShield)):
        out.append(f"**{title}**\n\n" + table(["field", "type", "default", "meaning"], _config_rows(cls)))
    return "\n\n".join(out)


def _folder(module: str, dirs: dict[str, str]) -> str:
    """The folder (with /) or file of roadload.<module> under setuptools package-dir."""
    if f"roadload.{module}" in dirs:
        return dirs[f"roadload.{module}"] + "/"
    path = Path(dirs["roadload"]) / module.replace(".", "/")
    return f"{path}/" if (ROOT / path).is_dir() else f"{path}.py"


def layers() -> str:
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contracts = cfg["tool"]["importlinter"]["contracts"]
    layered = next(c for c in contracts if c["type"] == "layers")
    dirs = cfg["tool"]["setuptools"]["package-dir"]
    rows = []
    for i, layer in enumerate(layered["layers"]):
        mods = [m.strip() for part in layer.split("|") for m in part.split(":")]
        folders = sorted({_folder(m, dirs) for m in mods})
        independent = "independent of each other" if "|" in layer else (
            "may import each other (no cycles)" if ":" in layer else "")
        rows.append([str(len(layered["layers"]) - i), ", ".join(f"`roadload.{m}`" for m in mods),
                     ", ".join(f"`{f}`" for f in folders), independent])
    others = [f"`{c['name']}` ({c['type']})" for c in contracts if c is not layered]
    return (table(["level (top imports below)", "packages", "folders", "within the level"], rows)
            + "\n\nOther contracts: " + "; ".join(others) + ".")


BLOCKS = {
    "estimators.md": {"catalog": estimator_catalog, "chapter5": chapter5},
    "force_models.md": {"models": force_models},
    "effects.md": {"presets": presets, "effects": effects},
    "sim2real.md": {"candidates": sim2real_candidates},
    "gym.md": {"config": gym_config},
    "architecture.md": {"layers": layers},
}


def render(page: Path, blocks: dict) -> str:
    text = page.read_text(encoding="utf-8")
    for name, make in blocks.items():
        pattern = re.compile(rf"(<!-- BEGIN generated: {name} -->\n).*?(<!-- END generated: {name} -->)", re.S)
        if not pattern.search(text):
            raise SystemExit(f"{page}: markers for generated block {name!r} are missing")
        body = make()
        text = pattern.sub(lambda m: m.group(1) + body + "\n" + m.group(2), text)
    return text


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="only check; exit 1 if a page is stale")
    parser.add_argument("--quick", action="store_true", help="the CI smoke run: same as --check")
    args = parser.parse_args()
    args.check = args.check or args.quick
    stale = []
    for page_name, blocks in BLOCKS.items():
        page = REFERENCE / page_name
        new = render(page, blocks)
        if new != page.read_text(encoding="utf-8"):
            stale.append(page_name)
            if not args.check:
                from roadload.fileio import write_text
                write_text(page, new)
    if args.check and stale:
        print(f"stale generated reference pages: {stale}; run python docs/tools/gen_reference.py", file=sys.stderr)
        return 1
    print(("up to date: " if args.check else "written: ") + ", ".join(stale or ["nothing changed"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
