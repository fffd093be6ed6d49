"""The guarantee at scale on the arm: docs/arm.md's table and its rows for notebook 05.

Runs the six sweeps the table reports (the UR5 and the Panda; the dynamic plant from
starts inside the energy bound, ``--velocity bounded``, and outside it,
``--velocity above``; the kinematic plant from rest), each through the command line as
a user would, then writes the rows the notebook reads
(``docs/data/arm_guarantee.parquet``: only its columns) and prints the table's lines and
the counts the text quotes.

    .venv/bin/python tools/arm_guarantee.py [--starts 10000] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "data" / "arm_guarantee.parquet"

#: (plant, velocity, the row's label) of the table's rows, per arm.
CASES = (
    ("dynamic", "bounded", "E0 < k_p"),
    ("dynamic", "above", "E0/k_p in [1.5, 4)"),
    ("kinematic", "bounded", "at rest"),
)
#: The arms: their name in the table and the command line's way to choose them.
ARMS = {"UR5": ["--carrier", "arm"], "Panda": ["--config", "{panda}"]}
COLUMNS = [
    "start", "status", "initial_energy_ratio", "max_energy_ratio", "monotone",
    "torque_clamped",
]  # fmt: skip


def _sweep(argv: list[str], out: Path) -> tuple[pd.DataFrame, float]:
    """One sweep through the CLI: its rows (:data:`COLUMNS`) and its wall time [s]."""
    command = [sys.executable, "-m", "geovs_drake.cli", "sweep", *argv, "--out", str(out)]
    print("$", " ".join(command[1:]), flush=True)
    subprocess.run(command, check=True)
    rows = pd.read_parquet(out / "results", columns=COLUMNS)
    wall = json.loads((out / "summary.json").read_text())["wall_time_s"]
    return rows.sort_values("start").reset_index(drop=True), float(wall)


def _line(label: str, rows: pd.DataFrame, wall: float) -> str:
    """The table's line: reached, the statuses, the clamp, energy rises, wall time."""
    reached = rows[rows.status != "unreachable"]
    count = reached.status.value_counts()
    cells = [
        len(reached), count.get("converged", 0), count.get("not_converged", 0),
        count.get("joint_limit", 0), count.get("left_domain", 0),
        int(reached.torque_clamped.sum()), int((~reached.monotone).sum()), f"{wall:.0f} s",
    ]  # fmt: skip
    return f"| {label} | " + " | ".join(map(str, cells)) + " |"


def _inside_bound(arm: str, rows: pd.DataFrame) -> str:
    """The counts the text quotes on the starts inside the bound: of those that left D,
    how many had their torque clamped and their energy rise; of the never-clamped ones,
    how many left D or had their energy rise."""
    reached = rows[rows.status != "unreachable"]
    left = reached[reached.status == "left_domain"]
    free = reached[~reached.torque_clamped]
    return (
        f"{arm} inside the bound: left D {len(left)} (clamped {int(left.torque_clamped.sum())},"
        f" energy rose {int((~left.monotone).sum())}); never clamped {len(free)}, of which "
        f"left D {int((free.status == 'left_domain').sum())}, energy rose "
        f"{int((~free.monotone).sum())}, converged {int((free.status == 'converged').sum())}"
    )


def main() -> None:
    """Run the sweeps, write the notebook's rows, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--starts", type=int, default=10_000)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    lines, notes, frames = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        panda = Path(tmp) / "panda.yaml"
        panda.write_text("carrier: !Arm {model: panda}\n")
        for arm, choose in ARMS.items():
            for plant, velocity, label in CASES:
                argv = [a.format(panda=panda) for a in choose]
                argv += ["--plant", plant, "--starts", str(args.starts)]
                argv += ["--workers", str(args.workers)]
                if plant == "dynamic":
                    argv += ["--velocity", velocity]
                rows, wall = _sweep(argv, Path(tmp) / f"{arm}-{plant}-{velocity}")
                lines.append(_line(f"{arm} {plant}, {label}", rows, wall))
                if plant == "dynamic" and velocity == "bounded":
                    notes.append(_inside_bound(arm, rows))
                frames.append(rows.assign(arm=arm, plant=plant, velocity=velocity))
    table = pd.concat(frames, ignore_index=True)
    for name in ("arm", "plant", "velocity", "status"):
        table[name] = table[name].astype("category")
    table["start"] = table["start"].astype("int32")
    for name in ("initial_energy_ratio", "max_energy_ratio"):
        table[name] = table[name].astype("float32")
    order = ["arm", "plant", "velocity", *COLUMNS]
    partial = OUT.with_suffix(".parquet.partial")  # written whole, then moved into place
    table[order].to_parquet(partial, index=False)
    partial.replace(OUT)
    print("\n".join(lines))
    print("\n".join(notes))
    cases = table.groupby(["arm", "plant", "velocity"], observed=True)
    unreachable = (cases.status.apply(lambda s: int((s == "unreachable").sum()))).to_dict()
    print(f"unreachable starts per case: {unreachable}; rows written to {OUT}")


if __name__ == "__main__":
    main()
