"""The seed's offset regressor: an MLP 400-300-200 (ReLU) from keypoint pixels to Δq (joints 1-3).

Inputs per sample (14): the 4 keypoints' pixels in the SRC reference resolution (1920×1080) and
the measured joints minus the calibration pose (so a servo that stops short of the pose is
accounted for); both standard-scaled with statistics stored in the module. Output: Δq̂ in
(rad, rad, m), de-scaled. One network per arm (the arms see the camera from mirrored sides).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from suture_bt.calibration.calibration_pose import CALIBRATION_JAW, CALIBRATION_POSES
from suture_bt.calibration.jaw_keypoints import NUM_KEYPOINTS
from suture_bt.calibration.scene_geometry import ARM_NAMES, REFERENCE_SIZE
from suture_bt.weights_file import WeightsError, load_state, load_weights_file, save_weights_file

HIDDEN = (400, 300, 200)
NUM_INPUTS = 2 * NUM_KEYPOINTS + 6
NUM_OUTPUTS = 3
WEIGHTS_PATH = Path(__file__).resolve().parent / "weights" / "offset_regressor.pt"
WEIGHTS_FORMAT = "suture_bt.offset_regressor.v1"
WEIGHTS_HINT = "run `suture-bt train calibration` to produce it (see README)"


def to_reference_pixels(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixels (…×2) of a width×height image expressed in the reference resolution."""
    sx, sy = REFERENCE_SIZE[0] / width, REFERENCE_SIZE[1] / height
    p = np.asarray(pixels, dtype=float)
    return np.stack([(p[..., 0] + 0.5) * sx - 0.5, (p[..., 1] + 0.5) * sy - 0.5], -1)


def regressor_features(arm: str, pixels_ref: np.ndarray, q_meas: np.ndarray) -> np.ndarray:
    """Raw (unscaled) inputs N×14 from reference pixels (N×4×2) and measured joints (N×6)."""
    pixels_ref = np.asarray(pixels_ref, dtype=float).reshape(-1, 2 * NUM_KEYPOINTS)
    q_meas = np.atleast_2d(np.asarray(q_meas, dtype=float))
    if q_meas.shape != (pixels_ref.shape[0], 6):
        raise ValueError(
            f"need one 6-joint vector per keypoint set, got {q_meas.shape} for "
            f"{pixels_ref.shape[0]} sets"
        )
    return np.concatenate([pixels_ref, q_meas - CALIBRATION_POSES[arm]], 1)


class OffsetMLP(nn.Module):
    """MLP 14 → 400 → 300 → 200 → 3 with ReLU and stored input/output standard scaling."""

    def __init__(self):
        super().__init__()
        sizes = (NUM_INPUTS, *HIDDEN)
        layers: list[nn.Module] = []
        for a, b in zip(sizes[:-1], sizes[1:], strict=True):
            layers += [nn.Linear(a, b), nn.ReLU()]
        layers.append(nn.Linear(sizes[-1], NUM_OUTPUTS))
        self.net = nn.Sequential(*layers)
        self.register_buffer("x_mean", torch.zeros(NUM_INPUTS, dtype=torch.float64))
        self.register_buffer("x_std", torch.ones(NUM_INPUTS, dtype=torch.float64))
        self.register_buffer("y_mean", torch.zeros(NUM_OUTPUTS, dtype=torch.float64))
        self.register_buffer("y_std", torch.ones(NUM_OUTPUTS, dtype=torch.float64))

    def set_scaling(self, x: np.ndarray, y: np.ndarray) -> None:
        """Fit the standard scalers to training inputs x (N×14) and targets y (N×3)."""
        for name, arr in (("x", x), ("y", y)):
            t = torch.as_tensor(np.asarray(arr), dtype=torch.float64)
            getattr(self, f"{name}_mean").copy_(t.mean(0))
            getattr(self, f"{name}_std").copy_(t.std(0).clamp_min(1e-12))

    def scale_x(self, x) -> torch.Tensor:
        x = torch.as_tensor(x, dtype=torch.float64)
        return ((x - self.x_mean) / self.x_std).float()

    def scale_y(self, y) -> torch.Tensor:
        y = torch.as_tensor(y, dtype=torch.float64)
        return ((y - self.y_mean) / self.y_std).float()

    def forward(self, x_scaled: torch.Tensor) -> torch.Tensor:
        """Scaled inputs → scaled outputs."""
        return self.net(x_scaled)

    @torch.no_grad()
    def predict(self, x: np.ndarray) -> np.ndarray:
        """Raw features (N×14) → Δq̂ (N×3, SI)."""
        out = self.forward(self.scale_x(np.atleast_2d(x))).double()
        return (out * self.y_std + self.y_mean).numpy()


@dataclass
class OffsetRegressor:
    """Both arms' MLPs plus what they were trained for; ``predict`` maps keypoints to Δq̂."""

    models: dict[str, OffsetMLP]
    meta: dict

    def predict(self, arm: str, pixels, width: int, height: int, q_meas) -> np.ndarray:
        """Δq̂ (N×3, SI) from keypoint pixels (N×4×2) in a width×height image and q_meas."""
        if arm not in self.models:
            raise ValueError(f"no regressor for arm {arm!r}; have {sorted(self.models)}")
        ref = to_reference_pixels(np.asarray(pixels).reshape(-1, NUM_KEYPOINTS, 2), width, height)
        q_meas = np.atleast_2d(q_meas)
        return self.models[arm].predict(regressor_features(arm, ref, q_meas))

    def save(self, path: Path = WEIGHTS_PATH) -> None:
        """Write both arms' weights and the (plain-typed) meta as a data-only file."""
        state = {arm: m.state_dict() for arm, m in self.models.items()}
        save_weights_file(path, WEIGHTS_FORMAT, state, self.meta)

    @classmethod
    def load(cls, path: Path = WEIGHTS_PATH) -> OffsetRegressor:
        """Load weights (data only, ``weights_only=True``); refuses a bad file and weights
        trained for another pose or jaw angle (WeightsError)."""
        state, meta = load_weights_file(path, WEIGHTS_FORMAT, WEIGHTS_HINT)
        if not state or not set(state) <= set(CALIBRATION_POSES):
            raise WeightsError(f"{path}: arms {sorted(state)} are not {ARM_NAMES}; {WEIGHTS_HINT}")
        try:
            poses, jaw = meta["poses"], float(meta["jaw"])
            wrong = [a for a in state if not np.allclose(poses[a], CALIBRATION_POSES[a])]
        except (KeyError, TypeError, ValueError) as exc:
            raise WeightsError(
                f"{path}: meta lacks valid poses/jaw ({exc!r}); {WEIGHTS_HINT}"
            ) from None
        if wrong:
            raise WeightsError(
                f"{path}: trained for another calibration pose of {wrong[0]}; {WEIGHTS_HINT}"
            )
        if abs(jaw - CALIBRATION_JAW) > 1e-9:
            raise WeightsError(
                f"{path}: trained for jaw angle {jaw}, not {CALIBRATION_JAW}; {WEIGHTS_HINT}"
            )
        models = {}
        for arm, sd in state.items():
            m = OffsetMLP()
            load_state(m, sd, path, WEIGHTS_HINT)
            models[arm] = m.eval()
        return cls(models, meta)


def new_regressor() -> OffsetRegressor:
    """Untrained regressor for both arms."""
    meta = {
        "poses": {a: CALIBRATION_POSES[a].tolist() for a in ARM_NAMES},
        "jaw": CALIBRATION_JAW,
        "reference_size": list(REFERENCE_SIZE),
    }
    return OffsetRegressor({a: OffsetMLP() for a in ARM_NAMES}, meta)
