"""configs/services/policy.yaml: the server, which declared policy it serves, how long a quiet
stream stays open and how large a camera's images may be."""

from __future__ import annotations

from pydantic import Field

from oricf.config import FilePath, Schema, config_dir
from oricf.imaging import MAX_PIXELS
from oricf.services.runtime import ServiceConfig

# A camera's image may always be as large as a full-HD frame, and larger for a network that
# takes large images: up to this many times its input's pixels.
FULL_HD_PIXELS = 1920 * 1080
INPUT_MULTIPLE = 64


class CameraImageSettings(Schema):
    max_pixels: int | None = Field(
        None, ge=1, le=MAX_PIXELS,
        description="refuse larger camera images; default: fitted to each camera's input, "
                    f"the larger of 1920x1080 and {INPUT_MULTIPLE} times its pixels")

    def limit(self, input_pixels: int) -> int:
        """The most pixels an image of a camera whose network input has input_pixels."""
        if self.max_pixels is not None:
            return self.max_pixels
        return min(MAX_PIXELS, max(FULL_HD_PIXELS, INPUT_MULTIPLE * input_pixels))


class PolicyConfig(ServiceConfig):
    model: FilePath = Field(
        default_factory=lambda: config_dir() / "models" / "policies" / "hopper.yaml",
        description="a declared policy (task: {kind: policy}; configs/models/policies/*.yaml)")
    stream_idle_s: float = Field(
        10.0, gt=0, le=3600,
        description="an ActStream that sends no observation for this long is closed "
                    "(DEADLINE_EXCEEDED), so quiet streams cannot keep others out")
    images: CameraImageSettings = Field(
        default_factory=CameraImageSettings, description="camera images in observations")
