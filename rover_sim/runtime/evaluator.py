"""The evaluator: the only part of a run that sees ground truth beside the estimates, and the one that scores them.

The pipeline hands it, at every tick, the true pose next to the onboard estimates, the contacts, and each VO step's
outcome with the true motion over the same interval; :meth:`Evaluator.metrics` turns them into :class:`Metrics`
and :func:`rover_sim.runtime.acceptance.judge` decides pass/fail against the scenario's criteria.

Slip is always measured from truth: per VO step (true progress along the previous heading over the wheel
odometry's commanded distance) when VO ran, otherwise over windows of ``SLIP_WINDOW_M`` of commanded travel from
the true along-heading progress, so a detour's curvature is not counted as slip.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from nav.geometry import se3_inv
from nav.trajectory import Pose, Trajectory, relative_errors
from rover_sim.runtime.pose_series import PoseSeries

# An accepted VO update whose translation error exceeds max(FALSE_POSITIVE_M, FALSE_POSITIVE_FRACTION x the true
# step) is a false positive (2 cm, or 5 % of a 35-75 cm step; MER VO's error was < 1 % of distance).
FALSE_POSITIVE_M = 0.02
FALSE_POSITIVE_FRACTION = 0.05


# A VO step is *textured* when at least this fraction of the ground seen by the left camera of both its pairs (the
# previous and the current) lies on texture: the scenario's ``[[appearance.texture_patches]]`` discs inside
# ``fine_soil``, or anywhere without ``fine_soil`` (see :meth:`rover_sim.world.world.World.textured_view_fraction`).
TEXTURED_VIEW_FRAC = 0.5


def false_positive_limit_m(step_m: float) -> float:
    """The largest translation error of an accepted update that is not a false positive, for a ``step_m`` step."""
    return max(FALSE_POSITIVE_M, FALSE_POSITIVE_FRACTION * abs(step_m))


SLIP_WINDOW_M = 0.35  # commanded travel per slip sample when there are no VO steps (MER's VO step)
FINAL_SLIP_WINDOW_M = 1.0  # the embedding check (purgatory_ripple): slip over the last metre of commanded travel
MIN_SLIP_TRAVEL_M = 0.05  # steps commanding less travel than this (turns in place) give no slip sample
# errors as a percentage of distance need a distance: below this path length (a mast-only run, a zero-length drive,
# a turn in place) the *_error_pct metrics are None (not measured) and only the errors in metres are reported
MIN_DISTANCE_FOR_PCT_M = 0.1
# KITTI-style segment lengths of travelled distance; a length is scored only when the drive is longer
SEGMENT_LENGTHS_M = (1.0, 5.0, 10.0)
# VO covariance consistency: segments of this much true travel (m) over consecutive accepted steps
NEES_SEGMENT_LENGTHS_M = (1.0, 5.0)
CHI2_3DOF_MEDIAN = 2.366  # median of a chi-square with 3 degrees of freedom: a consistent covariance's NEES


@dataclass
class VoStepRecord:
    t_s: float
    status: str
    commanded_m: float  # wheel-odometry distance since the previous pair
    vo_made_good_m: float  # VO-measured progress along the previous heading (NaN if no update)
    true_made_good_m: float
    vo_slip: float
    true_slip: float
    error_m: float  # |VO translation - true translation| (NaN if no update)
    n_inliers: int
    ms: float
    reason: str = ""  # why VO declined (empty when accepted)
    no_texture: bool = False  # the pointing search found no pointing with texture: a refusal here is justified
    true_step_m: float = math.nan  # |true translation| since the previous pair
    textured_frac: float = math.nan  # truth: the smaller textured fraction of the two pairs' ground views
    rotation_error_deg: float = math.nan  # angle between VO's and the true rotation of the step (NaN if no update)

    @property
    def false_positive(self) -> bool:
        return self.status == "ok" and self.error_m > false_positive_limit_m(self.true_step_m)

    @property
    def textured(self) -> bool:
        """Both pairs of the step see mostly textured ground (:data:`TEXTURED_VIEW_FRAC`, from truth)."""
        return self.textured_frac >= TEXTURED_VIEW_FRAC


@dataclass
class Metrics:
    """metrics.json (the core keys first, then extras)."""

    scenario: str
    seed: int
    distance_m: float
    dr_error_pct: float | None  # None when the path is shorter than MIN_DISTANCE_FOR_PCT_M
    vo_error_pct: float | None
    vo_convergence_pct: float | None
    max_slip_pct: float
    mean_slip_pct: float
    passed: bool
    reason: str
    wall_s: float
    halted: str | None = None
    dr_error_m: float = math.nan
    vo_error_m: float | None = None
    false_positives: int = 0
    vo_steps: int = 0
    vo_accepted: int = 0
    vo_refused_reasons: dict = field(default_factory=dict)  # refusal status -> count
    vo_refusals_justified: int = 0  # refusals on steps where no pointing had texture (logged; reported, not judged)
    pointing_changes: int = 0  # texture-seeking mast repointings
    max_vo_slip_pct: float | None = None
    body_collisions: int = 0  # ticks with the body (not a wheel) touching terrain or a rock
    tall_rock_contacts: int = 0  # ticks with any rover geom touching a rock >= TALL_ROCK_M tall
    goal_distance_m: float | None = None
    sim_s: float = 0.0
    # errors that do not hide: {"vo"|"dead_reckoning": {"1m": %, "5m": %, "10m": %}} (segments of
    # travelled distance, mean over every start record; "vo" None without VO) and the RMS of the position error
    # over every record of the drive (8 Hz, between VO updates too)
    kitti_segment_error_pct: dict = field(default_factory=dict)
    rms_position_error_m: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
    # VO over its textured steps (VoStepRecord.textured, from truth): every step after the first pair, a
    # re-initialisation included (it gives no motion); None when no step was textured
    vo_textured_steps: int = 0
    vo_textured_accepted: int = 0
    vo_textured_convergence_pct: float | None = None
    # KITTI-style rotational error of VO's accepted steps: the sum of each step's rotation error (deg) over their
    # true travel (m); None without accepted steps over MIN_DISTANCE_FOR_PCT_M
    vo_rotation_error_deg_per_m: float | None = None
    # wall-clock measurements: not deterministic, so written to timing.json rather than metrics.json
    timing: dict = field(default_factory=dict)

    @property
    def vo_step_ms_median(self) -> float | None:
        return self.timing.get("vo_step_ms_median")

    def deterministic_dict(self) -> dict:
        d = asdict(self)
        d.pop("timing")
        return d


def rotation_angle_deg(R: np.ndarray) -> float:
    """The angle of the rotation ``R`` (deg): the geodesic distance of two rotations ``A.T @ B``."""
    return math.degrees(math.acos(min(1.0, max(-1.0, 0.5 * (float(np.trace(R)) - 1.0)))))


def segment_errors_pct(
    estimate: Trajectory, truth: Trajectory, lengths_m: tuple[float, ...] = SEGMENT_LENGTHS_M
) -> dict[str, float]:
    """KITTI odometry metric (Geiger et al. 2012): for every start record and each length ``L`` shorter than the
    drive, the relative-pose translation error over the first ``L`` m of true travel, / ``L``; mean, in %."""
    lengths = [L for L in lengths_m if L < truth.path_length_m()]
    errs = relative_errors(estimate, truth, lengths, step_frames=1) if lengths else []
    return {f"{e.length_m:g}m": round(e.translation_error_pct, 3) for e in errs if e.n_segments}


@dataclass(frozen=True)
class VoStepError:
    """One accepted VO step's translation error and the translation covariance VO reported, both in the world frame
    (rotated by the true attitude at the previous pair); ``true_step_m`` is the true translation's length."""

    true_step_m: float
    error_m: np.ndarray  # (3,)
    cov_m2: np.ndarray  # (3, 3)


def nees(error: np.ndarray, cov: np.ndarray) -> float:
    """Normalised estimation error squared ``e^T C^-1 e`` (NaN if ``cov`` is singular or not finite)."""
    if not np.all(np.isfinite(cov)):
        return math.nan
    try:
        return float(error @ np.linalg.solve(cov, error))
    except np.linalg.LinAlgError:
        return math.nan


def vo_covariance_nees(
    steps: Sequence[VoStepError | None], lengths_m: tuple[float, ...] = NEES_SEGMENT_LENGTHS_M
) -> dict | None:
    """How well VO's reported covariances describe its errors (Bar-Shalom's NEES): the median over accepted steps of
    ``e^T C^-1 e`` (3 dof: about ``CHI2_3DOF_MEDIAN`` if consistent, larger if optimistic), and the same over
    non-overlapping runs of consecutive accepted steps covering ``L`` m of true travel, errors and covariances summed
    as if the steps were independent. A step error common to every step (a calibration bias) leaves the per-step
    figure near its own but grows the segment figure with ``L``; a ``None`` (a refused step) ends a run. None when
    no step has a finite covariance."""
    per_step = [nees(s.error_m, s.cov_m2) for s in steps if s is not None]
    per_step = [x for x in per_step if math.isfinite(x)]
    if not per_step:
        return None
    segments: dict[str, float | None] = {}
    for length in lengths_m:
        values, err, cov, travel = [], np.zeros(3), np.zeros((3, 3)), 0.0
        for s in steps:
            if s is None or not np.all(np.isfinite(s.cov_m2)):
                err, cov, travel = np.zeros(3), np.zeros((3, 3)), 0.0
                continue
            err, cov, travel = err + s.error_m, cov + s.cov_m2, travel + s.true_step_m
            if travel >= length:
                values.append(nees(err, cov))
                err, cov, travel = np.zeros(3), np.zeros((3, 3)), 0.0
        values = [v for v in values if math.isfinite(v)]
        segments[f"{length:g}m"] = round(float(np.median(values)), 2) if values else None
    return {
        "step_median": round(float(np.median(per_step)), 2),
        "segment_median": segments,
        "consistent_median": CHI2_3DOF_MEDIAN,
    }


def rms_position_error_m(estimate: Trajectory, truth: Trajectory) -> float:
    """Root mean square of ``|p_est - p_true|`` over every record (the sawtooth between VO updates included)."""
    d = np.linalg.norm(estimate.positions_xyz - truth.positions_xyz, axis=1)
    return round(float(np.sqrt(np.mean(d * d))), 4)


def step_slips(steps: Sequence[VoStepRecord]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The slip samples of a run's VO steps as ``metrics.json`` counts them (``max_slip_pct``, ``mean_slip_pct``,
    ``max_vo_slip_pct``) and ``plots/slip.png`` draws them: ``(t_s, true slip, VO slip)``, ratios, one per step
    commanding more than ``MIN_SLIP_TRAVEL_M`` (a shorter step's ratio divides by almost nothing); the VO slip is
    NaN where VO did not accept the step."""
    kept = [s for s in steps if abs(s.commanded_m) > MIN_SLIP_TRAVEL_M]
    t_s = np.array([s.t_s for s in kept], dtype=float)
    true = np.array([s.true_slip for s in kept], dtype=float)
    vo = np.array([s.vo_slip if s.status == "ok" else math.nan for s in kept], dtype=float)
    return t_s, true, vo


def window_slips(truth: Sequence[Pose], commanded_m: Sequence[float], window_m: float = SLIP_WINDOW_M) -> np.ndarray:
    """Slip over consecutive windows of ``window_m`` commanded travel: 1 - true along-heading progress / commanded.

    Progress is summed tick by tick along the true heading at the start of each tick (horizontal plane), so a
    curved path driven without slip scores about 0 and turns in place contribute nothing.
    """
    out: list[float] = []
    progress = commanded = 0.0
    for k in range(1, len(truth)):
        a, b = truth[k - 1], truth[k]
        x_axis = a.R_world_rover[:, 0]
        heading = x_axis[:2] / max(float(np.linalg.norm(x_axis[:2])), 1e-9)
        progress += float(np.dot(b.position_xyz_m[:2] - a.position_xyz_m[:2], heading))
        commanded += commanded_m[k] - commanded_m[k - 1]
        if abs(commanded) >= window_m:
            out.append(1.0 - progress / commanded)
            progress = commanded = 0.0
    return np.array(out, dtype=float)


def final_slip(
    truth: Sequence[Pose], commanded_m: Sequence[float], window_m: float = FINAL_SLIP_WINDOW_M
) -> float | None:
    """Slip over the last ``window_m`` of commanded travel (all of it if the drive was shorter): 1 - true
    along-heading progress / commanded, as in :func:`window_slips`; None below ``MIN_SLIP_TRAVEL_M`` commanded."""
    progress = commanded = 0.0
    for k in range(len(truth) - 1, 0, -1):
        if abs(commanded) >= window_m:
            break
        a, b = truth[k - 1], truth[k]
        x_axis = a.R_world_rover[:, 0]
        heading = x_axis[:2] / max(float(np.linalg.norm(x_axis[:2])), 1e-9)
        progress += float(np.dot(b.position_xyz_m[:2] - a.position_xyz_m[:2], heading))
        commanded += commanded_m[k] - commanded_m[k - 1]
    return 1.0 - progress / commanded if abs(commanded) >= MIN_SLIP_TRAVEL_M else None


def wheel_sinkage_m(centres_m: np.ndarray, ground_m: np.ndarray, radius_m: float) -> np.ndarray:
    """Depth of each wheel's bottom (centre minus radius) below the undisturbed ground under its centre, m."""
    return np.asarray(ground_m, dtype=float) - (np.asarray(centres_m, dtype=float)[:, 2] - radius_m)


class Evaluator:
    """Collects truth beside the estimates during a run; computes the metrics at the end."""

    def __init__(self, scenario_name: str, seed: int, goal_xy: np.ndarray | None, has_vo: bool) -> None:
        self.scenario_name, self.seed, self.goal_xy, self.has_vo = scenario_name, seed, goal_xy, has_vo
        self.truth = PoseSeries()  # compact arrays: a day-long drive keeps tens of thousands of each (pose_series.py)
        self.dr_poses = PoseSeries()
        self.onboard_poses = PoseSeries()
        self.commanded_m: list[float] = []  # wheel odometry's distance at each recorded pose
        self.vo_steps: list[VoStepRecord] = []
        self.vo_step_errors: list[VoStepError | None] = []  # accepted steps' errors and covariances; None: refused
        self.body_collision_ticks = 0
        self.tall_rock_contact_ticks = 0
        self.keep_out_info: dict | None = None
        self.sites: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (truth, DR, onboard) xyz at each site
        self._last_frame_truth: np.ndarray | None = None
        self._last_textured_frac = math.nan

    # ------------------------------------------------------------------ during the run
    def record(self, truth: Pose, dead_reckoning: Pose, onboard: Pose, commanded_m: float) -> None:
        self.truth.append(truth)
        self.dr_poses.append(dead_reckoning)
        self.onboard_poses.append(onboard)
        self.commanded_m.append(commanded_m)

    def count_contacts(self, body_contact: bool, tall_rock_contact: bool) -> None:
        self.body_collision_ticks += int(body_contact)
        self.tall_rock_contact_ticks += int(tall_rock_contact)

    @property
    def pair_textured_frac(self) -> float:
        """Truth: the textured fraction of the ground view of the last VO pair scored (NaN before any); a VO
        replayed on the same pairs scores its steps with it (:mod:`rover_sim.bench.replay`)."""
        return self._last_textured_frac

    def vo_step(
        self,
        truth: Pose,
        status: str,
        motion_rover: np.ndarray | None,
        commanded_m: float,
        n_inliers: int,
        ms: float,
        reason: str = "",
        no_texture: bool = False,
        covariance: np.ndarray | None = None,
        textured_frac: float = math.nan,
    ) -> VoStepRecord | None:
        """Score one VO step against the true motion since the previous pair (None for the first pair);
        ``covariance``: the 6x6 VO reported (translation first, previous rover frame), for its consistency;
        ``textured_frac``: the textured fraction of this pair's ground view (truth; the step takes the smaller of
        this pair's and the previous pair's)."""
        T_truth = truth.as_matrix()
        rec = None
        if self._last_frame_truth is not None and status != "first_frame":
            true_motion = se3_inv(self._last_frame_truth) @ T_truth
            true_good = float(true_motion[0, 3])
            vo_good, err, rot_err = math.nan, math.nan, math.nan
            ok = status == "ok"
            step_error = None
            if ok:
                vo_good = float(motion_rover[0, 3])
                err = float(np.linalg.norm(motion_rover[:3, 3] - true_motion[:3, 3]))
                rot_err = rotation_angle_deg(np.asarray(motion_rover, dtype=float)[:3, :3].T @ true_motion[:3, :3])
                if covariance is not None:
                    R = self._last_frame_truth[:3, :3]
                    C = np.asarray(covariance, dtype=float)[:3, :3]
                    e = R @ (np.asarray(motion_rover, dtype=float)[:3, 3] - true_motion[:3, 3])
                    step_error = VoStepError(float(np.linalg.norm(true_motion[:3, 3])), e, R @ C @ R.T)
            self.vo_step_errors.append(step_error)
            rec = VoStepRecord(
                truth.t_s,
                status,
                commanded_m,
                vo_good,
                true_good,
                1.0 - vo_good / commanded_m if abs(commanded_m) > 1e-3 and ok else math.nan,
                1.0 - true_good / commanded_m if abs(commanded_m) > 1e-3 else math.nan,
                err,
                n_inliers,
                ms,
                reason,
                no_texture,
                float(np.linalg.norm(true_motion[:3, 3])),
                min(textured_frac, self._last_textured_frac)
                if math.isfinite(textured_frac + self._last_textured_frac)
                else math.nan,
                rot_err,
            )
            self.vo_steps.append(rec)
        self._last_frame_truth = T_truth
        self._last_textured_frac = textured_frac
        return rec

    def site(self, truth: Pose, dead_reckoning: Pose, onboard: Pose) -> None:
        """A site (the end of a goto): where the rover is, beside where dead reckoning and the onboard pose put it."""
        self.sites.append((truth.position_xyz_m.copy(), dead_reckoning.position_xyz_m.copy(),
                           onboard.position_xyz_m.copy()))  # fmt: skip

    def site_errors(self) -> dict | None:
        """Horizontal position error at every site (m) of dead reckoning and of the onboard (VO-corrected) pose,
        and their means (None without sites)."""
        if not self.sites:
            return None
        truth, dr, onboard = (np.array(a)[:, :2] for a in zip(*self.sites, strict=True))
        e_dr, e_on = np.linalg.norm(dr - truth, axis=1), np.linalg.norm(onboard - truth, axis=1)
        return {
            "dead_reckoning_m": [round(float(v), 4) for v in e_dr],
            "onboard_m": [round(float(v), 4) for v in e_on],
            "dead_reckoning_mean_m": round(float(e_dr.mean()), 4),
            "onboard_mean_m": round(float(e_on.mean()), 4),
        }

    def keep_out(self, zone_name: str, onboard_d: float, dr_d: float, true_d: float) -> dict:
        self.keep_out_info = {
            "zone": zone_name,
            "onboard_distance_m": round(onboard_d, 3),
            "dead_reckoning_distance_m": round(dr_d, 3),
            "true_distance_m": round(true_d, 3),
        }
        return self.keep_out_info

    # ------------------------------------------------------------------ at the end
    def final_wheels(
        self, centres_m: np.ndarray, ground_m: np.ndarray, radius_m: float, law_sinkage_m: np.ndarray
    ) -> dict:
        """The wheels at the end of the run (``metrics.extra["wheels"]``): geometric sinkage below the undisturbed
        ground (mean and per wheel), the soil law's own sinkage (mean) and the slip over the last metre."""
        z = wheel_sinkage_m(centres_m, ground_m, radius_m)
        slip = final_slip(self.truth, self.commanded_m)
        return {
            "final_sinkage_m": round(float(np.mean(z)), 4),
            "final_sinkage_per_wheel_m": [round(float(v), 4) for v in z],
            "final_law_sinkage_m": round(float(np.mean(law_sinkage_m)), 4),
            "final_slip_pct": None if slip is None else round(100.0 * slip, 2),
        }

    def trajectories(self) -> dict[str, Trajectory]:
        out = {"truth": self.truth.trajectory(), "dead_reckoning": self.dr_poses.trajectory()}
        if self.has_vo:
            out["vo"] = self.onboard_poses.trajectory()
        return out

    def metrics(self, *, wall_s: float, sim_s: float, halted: str | None, extra: dict, timing: dict) -> Metrics:
        tr = self.trajectories()
        truth = tr["truth"]
        dist = truth.path_length_m()

        def pct(err: float | None) -> float | None:
            return round(100 * err / dist, 3) if err is not None and dist >= MIN_DISTANCE_FOR_PCT_M else None

        end = truth.positions_xyz[-1]
        dr_err = float(np.linalg.norm(tr["dead_reckoning"].positions_xyz[-1] - end))
        vo_err = float(np.linalg.norm(tr["vo"].positions_xyz[-1] - end)) if "vo" in tr else None
        steps = list(self.vo_steps)
        judged = [s for s in steps if s.status not in ("first_frame", "reinit")]
        accepted = [s for s in judged if s.status == "ok"]
        conv = 100.0 * len(accepted) / len(judged) if judged else None
        fps = sum(1 for s in accepted if s.false_positive)
        rot_m = sum(s.true_step_m for s in accepted)
        rot = sum(s.rotation_error_deg for s in accepted) / rot_m if rot_m > MIN_DISTANCE_FOR_PCT_M else None
        refused = [s for s in judged if s.status != "ok"]
        reasons: dict[str, int] = {}
        for s in refused:
            reasons[s.status] = reasons.get(s.status, 0) + 1
        _, true_slips, vo_slips = step_slips(steps)
        true_slips, vo_slips = true_slips[np.isfinite(true_slips)], vo_slips[np.isfinite(vo_slips)]
        if len(true_slips) == 0:  # no VO steps: slip over windows of commanded travel, from the true progress
            true_slips = window_slips(self.truth, self.commanded_m)
            if len(true_slips) == 0:
                true_slips = np.array([0.0])
        ms = [s.ms for s in steps]
        textured = [s for s in steps if s.textured]
        textured_ok = sum(1 for s in textured if s.status == "ok")
        sites = self.site_errors()
        return Metrics(
            scenario=self.scenario_name,
            seed=self.seed,
            distance_m=round(dist, 4),
            dr_error_pct=pct(dr_err),
            vo_error_pct=pct(vo_err),
            vo_convergence_pct=round(conv, 2) if conv is not None else None,
            vo_rotation_error_deg_per_m=round(rot, 4) if rot is not None else None,
            max_slip_pct=round(100 * float(np.max(true_slips)), 2),
            mean_slip_pct=round(100 * float(np.mean(true_slips)), 2),
            passed=False,
            reason="",
            wall_s=round(wall_s, 2),
            halted=halted,
            dr_error_m=round(dr_err, 4),
            vo_error_m=round(vo_err, 4) if vo_err is not None else None,
            false_positives=fps,
            vo_steps=len(judged),
            vo_accepted=len(accepted),
            vo_refused_reasons=dict(sorted(reasons.items())),
            vo_refusals_justified=sum(1 for s in refused if s.no_texture),
            max_vo_slip_pct=round(100 * float(np.max(vo_slips)), 2) if len(vo_slips) else None,
            body_collisions=self.body_collision_ticks,
            tall_rock_contacts=self.tall_rock_contact_ticks,
            goal_distance_m=round(float(np.linalg.norm(end[:2] - self.goal_xy)), 3)
            if self.goal_xy is not None
            else None,
            sim_s=round(sim_s, 2),
            kitti_segment_error_pct={
                k: segment_errors_pct(tr[k], truth) if k in tr else None for k in ("vo", "dead_reckoning")
            },
            rms_position_error_m={
                k: rms_position_error_m(tr[k], truth) if k in tr else None for k in ("vo", "dead_reckoning")
            },
            extra={
                "kitti_translation_error_pct": self.kitti(),
                "vo_covariance_nees": vo_covariance_nees(self.vo_step_errors),
            }
            | ({"sites": sites} if sites else {})
            | extra,
            timing={"vo_step_ms_median": round(float(np.median(ms)), 1) if ms else None} | timing,
            vo_textured_steps=len(textured),
            vo_textured_accepted=textured_ok,
            vo_textured_convergence_pct=round(100.0 * textured_ok / len(textured), 2) if textured else None,
        )

    def kitti(self) -> dict:
        """KITTI-style mean translational error (% of segment length) over sub-segments of 1, 2, 5 and 10 m."""
        tr = self.trajectories()
        truth = tr.pop("truth")
        lengths = [L for L in (1.0, 2.0, 5.0, 10.0) if L < truth.path_length_m()]
        out = {}
        for name, est in tr.items():
            errs = relative_errors(est, truth, lengths, step_frames=4) if lengths else []
            out[name] = {f"{e.length_m:g}m": round(e.translation_error_pct, 3) for e in errs}
        return out
