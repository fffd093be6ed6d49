"""Cost per pose of the camera map, its inverse and the Jacobian, N = 1 and N = 10^4.

Figures are ratios against a baseline measured in the same process: numpy's
batched 4x4 matrix inverse on the same poses (a fixed, well-known cost per
pose). Absolute times are printed for context only; the machine is shared.

    .venv/bin/python benchmarks/bench_camera_map.py
"""

from __future__ import annotations

import timeit

import numpy as np
from _record import Figure, record
from pydrake.math import RigidTransform

from geovs_drake import camera_map, camera_map_inverse, image_jacobian
from geovs_drake.sampling import random_visible_poses

RHO = 0.1


def per_call(fn, repeat: int = 5, number: int = 20) -> float:
    return min(timeit.repeat(fn, repeat=repeat, number=number)) / number


def main() -> None:
    rng = np.random.default_rng(0)
    X = random_visible_poses(rng, 10_000, RHO, (1.5, 50.0))
    y = camera_map(X, RHO)
    X1 = RigidTransform(X[0])
    y1 = camera_map(X1, RHO)

    base_batch = per_call(lambda: np.linalg.inv(X)) / len(X)
    base_single = per_call(lambda: np.linalg.inv(X[0]), number=2000)

    rows = [
        ("camera_map", lambda: camera_map(X1, RHO), lambda: camera_map(X, RHO)),
        (
            "camera_map_inverse",
            lambda: camera_map_inverse(y1, RHO),
            lambda: camera_map_inverse(y, RHO),
        ),
        ("image_jacobian", lambda: image_jacobian(y1, RHO), lambda: image_jacobian(y, RHO)),
    ]
    print("cost per pose, as a ratio to numpy's 4x4 inverse of the same batch size")
    print(f"{'function':<20} {'N=1 / base(N=1)':>16} {'N=1e4 / base(1e4)':>18} {'N=1 / N=1e4':>12}")
    figures = []
    for name, single, batch in rows:
        t1 = per_call(single, number=500)
        tN = per_call(batch, number=3) / len(X)
        print(f"{name:<20} {t1 / base_single:>16.1f} {tN / base_batch:>18.1f} {t1 / tN:>12.0f}")
        figures.append(
            Figure(f"{name}, one pose", t1 * 1e6, "us", "numpy 4x4 inverse, one", base_single * 1e6)
        )
        figures.append(
            Figure(
                f"{name}, per pose in a batch of 10^4",
                tN * 1e9,
                "ns",
                "numpy 4x4 inverse, batched",
                base_batch * 1e9,
            )
        )
    record("bench_camera_map", "The camera map and its Jacobian, per pose", figures)
    print(
        f"(context only: baseline {base_single * 1e6:.2f} us single, "
        f"{base_batch * 1e9:.1f} ns/pose batched)"
    )


if __name__ == "__main__":
    main()
