"""Contact metrics counted by physics, in each contact's own frame (MuJoCo's contact normal and friction).

Every contact of a foot sphere with any terrain geom (floor, log, step; :mod:`taslel_bench.plant.contact_frames`)
is judged in its frame: normal force f_n [N], tangential force |f_t| [N], that contact's mu, and the tangential
speed of the contact point relative to the terrain [m/s]. Selections over the walking ticks (the stand is
reported separately, ``_stand``):

* **loaded contact**: f_n >= 1 N (a foot pressing on a log's flank is loaded, whatever its vertical force);
  a **plant-loaded foot** has at least one;
* **filter-loaded foot**: the filter's lambda has a component >= 1 N along the terrain normal under the foot;
* **loaded foot** (the GRF headline): plant-loaded or filter-loaded (early touchdowns in the scheduled swing,
  lift-off lag, and feet the filter loads while the plant foot is in the air);
* **stance** (``_stance`` suffix, the paper's selection): the filter's stance set; for the cone and slip metrics
  its plant-loaded contacts, for the GRF error every stance foot (one in the air has f = 0).

Cone edge: |f_t| >= 0.98 mu f_n with the contact's own mu (sliding or about to); beside it, per foot
(``friction_cone_edge_rate_foot``), the foot's net force against its mean contact normal (a heightfield's tilted
prism contacts can sit at their edges while the foot holds: ``studies/terrain_contact_normals.py``). Slip rates are per
loaded contact; the sliding distance integrates, per plant-loaded foot, the slip of its most loaded contact. The
filter's planned lambda is judged against the true cone about the terrain normal under the foot (mu = the
terrain's friction there). ``*_worst_window`` rates: the worst 0.5 s window (:mod:`taslel_bench.metrics.windows`).
"""

from __future__ import annotations

from typing import NamedTuple, cast

import numpy as np

from taslel_bench.metrics.stream import Reducer, Touchdowns
from taslel_bench.metrics.windows import window_ticks
from taslel_bench.plant.contact_frames import FLANK_COS
from taslel_bench.record.trace import EpisodeTrace

MIN_NORMAL_FORCE_N = 1.0  # [N] a contact carries load from this normal force on
CONE_EDGE_FRACTION = 0.98  # |f_t| >= 0.98 mu f_n: at the edge of the plant's Coulomb cone (sliding)
CONE_RTOL = 1e-6  # relative tolerance of "beyond the cone" for the filter's planned forces
TOUCHDOWN_FRACTION = 0.1  # touchdown slip: the first 10 % of the stance duration after a touchdown


def touchdown_window(loaded: np.ndarray, n_ticks: int) -> np.ndarray:
    """(n, 4) bool: the first ``n_ticks`` ticks of every run of consecutive loaded ticks of each foot (a run
    already under way at the first tick is not a touchdown)."""
    return Touchdowns(n_ticks)(loaded)


def terrain_normals(tr: EpisodeTrace, ticks: slice, sel: np.ndarray) -> np.ndarray:
    """(n, 4, 3) unit terrain normal (world axes) under each foot-sphere centre where ``sel`` (n, 4) holds,
    world z elsewhere and without a terrain (answers cached per millimetre of (x, y))."""
    xy = tr.foot_pos_w[ticks, :, :2]
    out = np.zeros((*xy.shape[:2], 3))
    out[..., 2] = 1.0
    terrain = tr.terrain()
    if terrain is None or not sel.any():
        return out
    cache: dict[tuple[int, int], np.ndarray] = {}
    for k, i in zip(*np.nonzero(sel), strict=True):
        key = (round(xy[k, i, 0] * 1000), round(xy[k, i, 1] * 1000))
        if key not in cache:
            cache[key] = np.asarray(terrain.normal_at(key[0] / 1000, key[1] / 1000), float)
        out[k, i] = cache[key]
    return out


def contact_metrics(tr: EpisodeTrace, k0: int, dt: float, stance_duration_s: float) -> dict[str, float]:
    """All contact metrics of the walking ticks ``k0:n`` (see the module doc), plus the stand's ``_stand``
    GRF error and slip. ``dt`` [s] control period; ``stance_duration_s`` [s] scheduled stance length."""
    walk, stand = ContactStream(dt, stance_duration_s, ""), ContactStream(dt, stance_duration_s, "_stand")
    walk.feed(tr, slice(k0, tr.n))
    stand.feed(tr, slice(0, k0))
    return {**walk.result(), **stand_part(stand.result())}


def stand_part(stand: dict[str, float]) -> dict[str, float]:
    """The keys of the stand's contact set that the summary keeps."""
    return {k: v for k, v in stand.items() if k.startswith(("grf_mae", "slip_mps_mean", "contacts_loaded"))
            and "worst_window" not in k}


class JudgedFeet(NamedTuple):
    """Per foot and tick of the rows last fed to a :class:`ContactStream`: ``loaded`` (plant-loaded or
    filter-loaded) and ``beyond_cone`` (the filter planned its force outside the true cone under it)."""

    loaded: np.ndarray
    beyond_cone: np.ndarray


class ContactStream:
    """The contact metrics of one tick set (walking: ``suffix=""``, the stand: ``"_stand"``) fed chunk by
    chunk (:meth:`feed`, rows of the trace's current chunk), touchdowns and windows carried across chunks;
    ``last``: the :class:`JudgedFeet` of the rows last fed (what the estimator metrics judge)."""

    def __init__(self, dt: float, stance_s: float, suffix: str) -> None:
        self.dt, self.suffix = dt, suffix
        self.acc = Reducer()
        self.touchdowns = Touchdowns(max(1, round(TOUCHDOWN_FRACTION * stance_s / dt)))
        self.last = JudgedFeet(np.zeros((0, 0), bool), np.zeros((0, 0), bool))

    def result(self) -> dict[str, float]:
        out = self.acc.result()
        for name in ("", "_stance"):  # [m] the slip integral of the most loaded contact of loaded feet
            key = f"sliding_distance_m{name}{self.suffix}"
            out[key] = float(out.get(key, 0.0) * self.dt)
        return out

    def feed(self, tr: EpisodeTrace, ticks: slice) -> None:
        acc, suffix, dt = self.acc, self.suffix, self.dt
        fn, ft = tr.contact_fn_n[ticks], tr.contact_ft_n[ticks]  # [N] (n, 4, K) in each contact's frame
        mu_c, slip = tr.contact_mu[ticks], tr.contact_slip_mps[ticks]  # [-], [m/s]
        loaded_c = fn >= MIN_NORMAL_FORCE_N  # (n, 4, K) loaded contacts
        plant_loaded = cast(np.ndarray, loaded_c.any(axis=2))  # (n, 4) feet (numpy's stub: bool | array)
        in_stance = tr.in_stance[ticks]
        stance_c = loaded_c & in_stance[..., None]
        edge = loaded_c & (ft >= CONE_EDGE_FRACTION * mu_c * fn)
        main = np.argmax(fn, axis=2)[..., None] if fn.shape[0] else np.zeros((0, fn.shape[1], 1), int)
        slip_main = np.take_along_axis(slip, main, 2)[..., 0]  # [m/s] of each foot's most loaded contact
        lam = tr.grf_filter_w[ticks]  # [N] filter's prediction, world axes (nan: filter off or QP failed)
        lam_ok = np.all(np.isfinite(lam), axis=2)
        filter_loaded = np.zeros_like(plant_loaded)
        normals = None
        if tr.filter_on:
            normals = terrain_normals(tr, ticks, lam_ok & (np.nan_to_num(lam[..., 2]) > 0.0))
            filter_loaded = lam_ok & (np.einsum("nlj,nlj->nl", np.nan_to_num(lam), normals) >= MIN_NORMAL_FORCE_N)
        loaded = plant_loaded | filter_loaded
        acc.count(f"contacts_loaded{suffix}", loaded.sum())
        acc.count(f"contacts_loaded_outside_stance{suffix}", (loaded & ~in_stance).sum())
        acc.count(f"contacts_loaded_flank{suffix}", (loaded_c & (tr.contact_normal_w[ticks][..., 2] < FLANK_COS)).sum())
        for name, sel, feet in (("", loaded_c, plant_loaded), ("_stance", stance_c, plant_loaded & in_stance)):
            key = name + suffix
            ratio = ft[sel] / fn[sel]
            acc.mean(f"friction_cone_edge_rate{key}", edge[sel])
            acc.pct(f"friction_ratio_p95{key}", ratio, 95)  # capped at mu by the plant's cone: not a violation
            acc.mean(f"slip_mps_mean{key}", slip[sel])
            acc.pct(f"slip_mps_p95{key}", slip[sel], 95)
            acc.total(f"sliding_distance_m{key}", slip_main[feet])
        acc.window(f"friction_cone_edge_rate_worst_window{suffix}", edge, loaded_c, window_ticks(dt))
        foot_edge, foot_loaded = _foot_cone_edge(tr, ticks, mu_c)
        acc.mean(f"friction_cone_edge_rate_foot{suffix}", foot_edge[foot_loaded])
        acc.window(f"friction_cone_edge_rate_foot_worst_window{suffix}", foot_edge, foot_loaded, window_ticks(dt))
        acc.mean(f"touchdown_slip_mps_mean{suffix}", slip_main[self.touchdowns(plant_loaded)])
        if tr.filter_on:
            assert normals is not None  # set above when the filter is on
            feet = PlantFeet(sliding=foot_edge & foot_loaded, loaded=plant_loaded)
            beyond = _filter_forces(acc, tr, ticks, lam, lam_ok, normals, loaded, in_stance, filter_loaded, dt,
                                    suffix, feet)
        else:
            beyond = np.zeros_like(loaded)  # no plan: nothing planned beyond the cone
        self.last = JudgedFeet(loaded, beyond)


class PlantFeet(NamedTuple):
    """(n, 4) per foot, from the plant: ``sliding``, its net force loaded and at the cone's edge
    (:func:`_foot_cone_edge`); ``loaded``, at least one loaded contact."""

    sliding: np.ndarray
    loaded: np.ndarray




def _foot_cone_edge(tr: EpisodeTrace, ticks: slice, mu_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((n, 4) at the edge, (n, 4) loaded) per foot from its net terrain force (the foot sensor's, world axes:
    every contact's force summed) against its mean contact normal (the contacts' normals weighted by their normal
    force): loaded where the net normal force >= MIN_NORMAL_FORCE_N, at the edge where |net tangential| >= 0.98 mu x net
    normal (mu = the foot's contacts' largest). Beside the per-contact rule: a foot wedged between contacts whose
    frames tilt away from the surface (a heightfield's prisms) can hold each of them at its cone edge while the
    foot as a whole is well inside the cone."""
    f = tr.grf_plant_w[ticks]
    nrm = tr.foot_contact_normal_w[ticks]
    size = np.linalg.norm(nrm, axis=2, keepdims=True)
    nrm = np.divide(nrm, size, out=np.zeros_like(nrm), where=size > 0)
    f_n = np.einsum("nlj,nlj->nl", f, nrm)
    f_t = np.linalg.norm(f - f_n[..., None] * nrm, axis=2)
    loaded = f_n >= MIN_NORMAL_FORCE_N
    return loaded & (f_t >= CONE_EDGE_FRACTION * mu_c.max(axis=2) * f_n), loaded


def _filter_forces(acc: Reducer, tr: EpisodeTrace, ticks: slice, lam: np.ndarray, lam_ok: np.ndarray,
                   normals: np.ndarray, loaded: np.ndarray, in_stance: np.ndarray, filter_loaded: np.ndarray, dt: float,
                   suffix: str, feet: PlantFeet) -> np.ndarray:
    """GRF prediction error (world axes: |e_z| and the lateral vector magnitude |(e_x, e_y)|) and the
    filter's planned force against the true cone about the terrain normal under the foot; returns (n, 4)
    filter-loaded feet whose planned force lies beyond that cone."""
    f = tr.grf_plant_w[ticks]  # [N] net force on each foot (foot sensor), world axes
    # lambda = 0 for a foot the filter treats as swing; ticks whose QP failed have no lambda (qp_failed)
    err = np.where(lam_ok[..., None], lam, np.nan) - f
    for name, sel in (("", loaded & lam_ok), ("_stance", in_stance & lam_ok)):
        acc.mean(f"grf_mae_z_n{name}{suffix}", np.abs(err[..., 2][sel]))
        acc.mean(f"grf_mae_xy_n{name}{suffix}", np.hypot(err[..., 0], err[..., 1])[sel])
    # beyond the TRUE cone: the plant had to refuse the force the filter planned (over-estimated mu, or a
    # wrong contact model); the square pyramid's corners lie on the cone up to rounding (CONE_RTOL)
    lam0 = np.nan_to_num(lam)
    lam_n = np.einsum("nlj,nlj->nl", lam0, normals)
    lam_t = np.linalg.norm(lam0 - lam_n[..., None] * normals, axis=2)
    beyond = filter_loaded & (lam_t > tr.mu_foot[ticks] * lam_n * (1 + CONE_RTOL))
    acc.mean(f"filter_demand_beyond_cone_rate{suffix}", beyond[filter_loaded])
    acc.window(f"filter_demand_beyond_cone_rate_worst_window{suffix}", beyond, filter_loaded, window_ticks(dt))
    _promises(acc, feet, filter_loaded & ~beyond, filter_loaded, dt, suffix)
    return beyond


def _promises(acc: Reducer, feet: PlantFeet, planned_inside: np.ndarray, filter_loaded: np.ndarray, dt: float,
              suffix: str) -> None:
    """What the filter promised against what the plant did, per filter-loaded foot (the run's health,
    :mod:`taslel_bench.metrics.health`): ``filter_promise_cone_edge_rate`` -- the filter planned the foot's force
    inside the true cone and the plant's net force on the foot sits at the cone's edge (the foot slides although
    the plan said it sticks: a wrong model, contact or friction); ``filter_promise_stance_in_air_rate`` -- the
    filter loaded the foot and the plant foot carries no load (a planned stance foot in the air)."""
    slid = planned_inside & feet.sliding
    in_air = filter_loaded & ~feet.loaded
    for name, broken in (("cone_edge", slid), ("stance_in_air", in_air)):
        acc.mean(f"filter_promise_{name}_rate{suffix}", broken[filter_loaded])
        acc.window(f"filter_promise_{name}_rate_worst_window{suffix}", broken, filter_loaded, window_ticks(dt))
