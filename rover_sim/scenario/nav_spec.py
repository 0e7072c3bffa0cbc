"""``[nav]``: the navigation stack's configuration: VO, stereo and planner (built-in or a plugin, with their
parameters), VO stepping, the camera, image size, mast pointing, speed and slip limit."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field, model_validator

from nav.gestalt import GestaltParams
from nav.stereo import StereoParams
from nav.vo import SanityConstraints, VoParams
from rover_sim.scenario.base import Spec

BUILTIN = "builtin"
IMPL_DESCRIPTION = (
    '"builtin", an import path "package.module:Class", or the name of an entry point in the group "rover_sim.plugins"'
)


def _split_params(data: Any, own: tuple[str, ...], shorthand: str | None) -> Any:
    """Let a ``[nav.<part>]`` table hold its algorithm parameters flat (``--set nav.vo.window_px=9``).

    Keys that are not the part's own settings go into ``params``; a bare bool or string is shorthand for
    ``enabled`` or ``impl`` (``[nav] vo = false``, ``vo = "mypkg.vo:MyVO"``).
    """
    if isinstance(data, bool) and shorthand == "enabled":
        return {"enabled": data}
    if isinstance(data, str):
        return {"impl": data}
    if not isinstance(data, dict):
        return data
    out = {k: v for k, v in data.items() if k in own or k == "params"}
    flat = {k: v for k, v in data.items() if k not in out}
    if flat:
        out["params"] = {**(out.get("params") or {}), **flat}
    return out


class VoSpec(Spec):
    """``[nav.vo]``: visual odometry on/off, which implementation, its parameters and MER's sanity constraints."""

    enabled: bool = Field(True, description="Visual odometry on (MER used it on slopes and in sand).")
    impl: str = Field(BUILTIN, min_length=1, description=IMPL_DESCRIPTION)
    sanity: SanityConstraints = Field(default_factory=SanityConstraints)
    params: VoParams = Field(default_factory=VoParams)
    shadow_mask: bool = Field(True, description="Bar features in and near the rover's predicted shadow.")
    seek_texture: bool = Field(True, description="Repoint the mast at texture when the planned view is poor.")
    update: Literal["position", "full_pose"] = Field(
        "position",
        description="What an accepted VO step corrects: 'position' (MER: the IMU keeps attitude) or "
        "'full_pose' (attitude too).",
    )

    @model_validator(mode="before")
    @classmethod
    def _flat(cls, data: Any) -> Any:
        own = ("enabled", "impl", "sanity", "shadow_mask", "seek_texture", "update")
        return _split_params(data, own, "enabled")


class StereoSpec(Spec):
    """``[nav.stereo]``: the dense stereo used for autonav ranging and the recording's depth."""

    impl: str = Field(BUILTIN, min_length=1, description=IMPL_DESCRIPTION)
    params: StereoParams = Field(default_factory=StereoParams)

    @model_validator(mode="before")
    @classmethod
    def _flat(cls, data: Any) -> Any:
        return _split_params(data, ("impl",), None)


class PlannerSpec(Spec):
    """``[nav.planner]``: the autonav planner (GESTALT by default) and its parameters."""

    impl: str = Field(BUILTIN, min_length=1, description=IMPL_DESCRIPTION)
    params: GestaltParams = Field(default_factory=GestaltParams)

    @model_validator(mode="before")
    @classmethod
    def _flat(cls, data: Any) -> Any:
        return _split_params(data, ("impl",), None)


class NavSpec(Spec):
    vo: VoSpec = Field(default_factory=VoSpec)
    stereo: StereoSpec = Field(default_factory=StereoSpec)
    planner: PlannerSpec = Field(default_factory=PlannerSpec)
    vo_step_m: float = Field(0.35, gt=0.05, le=0.75, description="Drive between VO images (MER: <= 75 cm).")
    camera: Literal["navcam", "hazcam_front"] = "navcam"
    resolution_px: int = Field(256, ge=64, le=1024, description="Navigation image size (MER binned to 256).")
    mast_pan_deg: float = Field(0.0, ge=-180.0, le=180.0)
    mast_tilt_deg: float = Field(
        -40.0, ge=-70.0, le=85.0, description="Navcam elevation: negative looks down (joint range -74..+86 deg)."
    )
    speed_m_s: float = Field(0.0375, gt=0.0, le=0.05, description="Wheel speed (MER peak 5 cm/s).")
    slip_limit: float | None = Field(
        None, gt=0.0, le=2.0, description="Halt when a VO step measures more slip than this (MER: 0.4)."
    )
    image_noise: bool = True
    epipolar_check: bool = Field(
        True,
        description="Flight profile: fit each stereo pair's relative pitch and roll from its first images' row "
        "disparities and rectify with the corrected calibration (nav/epipolar.py).",
    )
