"""Are the cone-edge contacts on a world the feet sliding, or contacts whose frame disagrees with the surface?
(``python -m studies.terrain_contact_normals [--out FILE.md]``)

For each world and controller (seed, 0.5 s stand + 5 s trot, ``+experiment=terrain``, the URDF plant), every
loaded foot contact (MuJoCo normal force > 1 N) of a foot past x = 0.8 m (on the relief, after the start) in the
walking ticks, in MuJoCo's contact frame as the harness counts it (:mod:`taslel_bench.plant.contact_frames`): the
share at the cone edge (|f_t| >= 0.98 mu f_n, the verdict's ``cone_edge`` rule), and the angle between the
contact's normal and the terrain's surface normal under the foot centre (``Terrain.normal_at``; the contact
point is within the foot radius, 2 cm, of it). Columns: edge share; the
share of the edge contacts whose normal is more than 20 deg off the surface; the edge share among contacts
within 5 deg of the surface; the contact-point slip speed (median) of edge and of other contacts [m/s].
"""

from __future__ import annotations

import numpy as np

from studies.study_table import table_study
from taslel_bench import api

CASES = (("rough", "filter.enabled=false", 0), ("rough", "filter=terrain", 0), ("rough", "filter=terrain", 1),
         ("steps", "filter=terrain", 0), ("slope", "filter=terrain", 0), ("logs", "filter=terrain", 0))
LOADED_N, FROM_X_M, OFF_DEG, ON_DEG = 1.0, 0.8, 20.0, 5.0


def row(world: str, controller: str, seed: int) -> str:
    from taslel_bench.sim.build import Built

    cfg = api.compose(["+experiment=terrain", f"scenario={world}", controller, "duration=5", f"seed={seed}",
                       "record.mcap=false", "progress=false"])
    built = Built(cfg)
    tr = built.episode.run().trace
    tr.finalize()
    terrain, n = built.episode.terrain, tr.n
    k0 = round(float(cfg.controller.stand_duration) * float(cfg.control_rate_hz))
    fn, ft, mu = tr.contact_fn_n[k0:n], np.abs(tr.contact_ft_n[k0:n]), tr.contact_mu[k0:n]  # (ticks, legs, k)
    feet = tr.foot_pos_w[k0:n]  # (ticks, legs, 3) [m]
    keep = (fn > LOADED_N) & (feet[:, :, None, 0] > FROM_X_M)
    t_i, leg_i, _ = np.nonzero(keep)
    normal = tr.contact_normal_w[k0:n][keep]
    normal *= np.sign(normal[:, 2:3])  # out of the terrain
    xy = feet[t_i, leg_i, :2]  # the foot centre's xy for the surface under the contact (foot radius 2 cm)
    surface = np.array([np.asarray(terrain.normal_at(x, y), float) for x, y in xy])
    off = np.degrees(np.arccos(np.clip((normal * surface).sum(axis=1), -1.0, 1.0)))
    edge = ft[keep] >= 0.98 * mu[keep] * fn[keep]
    slip = tr.contact_slip_mps[k0:n][keep]
    return (f"| {world} | {controller} | {seed} | {len(edge)} | {edge.mean():.3f} | {(off[edge] > OFF_DEG).mean():.2f} "
            f"| {edge[off < ON_DEG].mean():.3f} | {np.median(slip[edge]):.3f} | {np.median(slip[~edge]):.3f} |")


def main(argv: list[str] | None = None) -> None:
    header = [("| world | controller | seed | loaded contacts | cone-edge share | edge contacts > 20 deg off the "
               "surface | edge share within 5 deg of the surface | slip at edge [m/s] | slip elsewhere [m/s] |"),
              "|---|---|---|---|---|---|---|---|---|"]
    table_study("studies.terrain_contact_normals", __doc__, header, (row(*case) for case in CASES), argv)

if __name__ == "__main__":
    main()
