"""The base of every scenario table: unknown fields are errors; values are frozen, finite and validated, defaults
too."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class Spec(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False, validate_default=True)
