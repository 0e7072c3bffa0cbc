"""Static hazcam looks at rocks on one `bench autonav` field (docs/navigation/autonav-tall-rocks.md).

The rover is placed 1.3, 1.9 and 2.6 m from randomly chosen rocks of 14-45 cm (its footprint clear of rocks >= 10
cm), facing them; the front hazcam pair is taken and matched as autonav does (onboard calibration, rectification,
SAD stereo). Kept per look: the rover-frame range points and the true pose, plus the field's rock list. Truth places
the rover and scores the result; nothing here is onboard code.

    MUJOCO_GL=egl python sample_looks.py SEED OUT.npz [ROCKS]
"""

from __future__ import annotations

import math
import sys

import numpy as np

from rover_sim.bench.autonav import field_scenario
from rover_sim.mission.onboard import terrain_points
from rover_sim.mission.pipeline import Mission
from rover_sim.mission.scenario import scenario_from_dict

HAZCAM = "hazcam_front"
RANGES_M = (1.3, 1.9, 2.6)


def main(seed: int, out: str, n_rocks: int = 10) -> None:
    rng = np.random.default_rng(1000 + seed)
    mission = Mission(scenario_from_dict(field_scenario(seed), source=f"autonav field {seed}"))
    world = mission.world
    world.calibrate(HAZCAM)
    rocks = world.terrain.rocks
    R = np.array([[r.x_m, r.y_m, r.height_m, 0.5 * max(r.length_m, r.width_m)] for r in rocks])
    chosen = [k for k, r in enumerate(rocks) if 0.14 <= r.height_m <= 0.45 and abs(r.y_m) < 6 and abs(r.x_m) < 11]
    rng.shuffle(chosen)
    looks = []
    for k in chosen:
        if len(looks) >= len(RANGES_M) * n_rocks:
            break
        r = rocks[k]
        for d in RANGES_M:
            for _ in range(16):
                ang = rng.uniform(-math.pi, math.pi)
                off = rng.uniform(-0.3, 0.3)
                x = r.x_m - d * math.cos(ang) - off * math.sin(ang)
                y = r.y_m - d * math.sin(ang) + off * math.cos(ang)
                gap = np.hypot(R[:, 0] - x, R[:, 1] - y) - R[:, 3]
                if not (np.any((gap < 0.95) & (R[:, 2] >= 0.10)) or abs(x) > 12 or abs(y) > 6.5):
                    break
            else:
                continue
            world.sim.place(x, y, math.atan2(r.y_m - y, r.x_m - x), settle_s=0.3)
            obs = world.observation_with([], [], {HAZCAM: world.render(HAZCAM)})
            pts = terrain_points(mission.onboard.range_image(obs, HAZCAM).points_rover_m()).astype(np.float32)
            looks.append((k, d, world.truth_pose().as_matrix(), pts))
    np.savez_compressed(
        out,
        rocks=np.array([[r.x_m, r.y_m, r.z_base_m, r.length_m, r.width_m, r.height_m, r.yaw_rad] for r in rocks]),
        shapes=np.array([r.shape for r in rocks]),
        target=np.array([lk[0] for lk in looks]),
        d=np.array([lk[1] for lk in looks]),
        T=np.array([lk[2] for lk in looks]),
        npts=np.array([len(lk[3]) for lk in looks]),
        pts=np.concatenate([lk[3] for lk in looks]) if looks else np.zeros((0, 3), np.float32),
    )
    print(f"field {seed}: {len(looks)} looks -> {out}")
    mission.close()


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 10)
