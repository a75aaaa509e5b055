"""Stage timing and units: what every facedyn layer copies from its input."""
from __future__ import annotations

from dataclasses import dataclass

from pxr import Sdf, Usd, UsdGeom


@dataclass(frozen=True)
class Timing:
    """Timing and unit metadata of a take (copied onto every layer written for it)."""

    time_codes_per_second: float
    frames_per_second: float
    start_time_code: float
    end_time_code: float
    meters_per_unit: float = 0.01
    up_axis: str = "Y"

    @classmethod
    def from_stage(cls, stage: Usd.Stage) -> "Timing":
        return cls(
            time_codes_per_second=float(stage.GetTimeCodesPerSecond()),
            frames_per_second=float(stage.GetFramesPerSecond()),
            start_time_code=float(stage.GetStartTimeCode()),
            end_time_code=float(stage.GetEndTimeCode()),
            meters_per_unit=float(UsdGeom.GetStageMetersPerUnit(stage)),
            up_axis=str(UsdGeom.GetStageUpAxis(stage)),
        )

    def with_frames(self, first: float, last: float) -> "Timing":
        return Timing(
            self.time_codes_per_second, self.frames_per_second, first, last, self.meters_per_unit, self.up_axis
        )

    def apply(self, layer: Sdf.Layer) -> None:
        """Author this timing and the units on a layer's metadata."""
        layer.timeCodesPerSecond = self.time_codes_per_second
        layer.framesPerSecond = self.frames_per_second
        layer.startTimeCode = self.start_time_code
        layer.endTimeCode = self.end_time_code
        pseudo_root = layer.pseudoRoot
        pseudo_root.SetInfo(UsdGeom.Tokens.metersPerUnit, self.meters_per_unit)
        pseudo_root.SetInfo(UsdGeom.Tokens.upAxis, self.up_axis)

    @classmethod
    def from_layer(cls, layer: Sdf.Layer) -> "Timing":
        info = layer.pseudoRoot
        has = info.HasInfo
        return cls(
            time_codes_per_second=float(layer.timeCodesPerSecond),
            frames_per_second=float(layer.framesPerSecond),
            start_time_code=float(layer.startTimeCode),
            end_time_code=float(layer.endTimeCode),
            meters_per_unit=float(info.GetInfo(UsdGeom.Tokens.metersPerUnit)) if has(UsdGeom.Tokens.metersPerUnit) else 0.01,
            up_axis=str(info.GetInfo(UsdGeom.Tokens.upAxis)) if has(UsdGeom.Tokens.upAxis) else "Y",
        )
