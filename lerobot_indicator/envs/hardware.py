"""Camera and end-effector settings shaped like LeRobot's real-hardware configs, honoured by the sim.

One YAML then describes both the simulated task and the real setup it stands for (the paper's Sawyer
with a RealSense D435): ``RealSenseCameraConfig`` fields for the camera, ``end_effector_bounds`` /
``end_effector_step_sizes`` as LeRobot's end-effector processors take them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

CAMERA_TYPES = ("sim", "intelrealsense")
AXES = ("x", "y", "z")


@dataclass
class GoalCameraConfig:
    """A fixed RGB-D camera. ``type: intelrealsense`` adds what LeRobot needs to open the real one."""

    type: str = "sim"
    name: str = "front"
    serial_number_or_name: str | None = None
    fps: int = 30
    width: int = 100
    height: int = 100
    use_depth: bool = True
    # Vertical field of view (degrees): 58 is the D435 depth sensor's.
    fovy_deg: float = 58.0
    # Depth outside [depth_min_m, depth_max_m] reads 0 (invalid), as on a RealSense.
    depth_min_m: float = 0.1
    depth_max_m: float = 3.0
    # Camera pose in the sim world frame (metres); the real camera's pose is wherever it is mounted.
    pos: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.5])
    lookat: list[float] = field(default_factory=lambda: [-0.15, 0.0, 1.08])
    # Simulation only: render at supersample x (height, width) and average each supersample x supersample block
    # (area averaging, anti-aliasing) down to (height, width); the observation keeps its size and dtypes.
    supersample: int = 1

    def __post_init__(self):
        if self.type not in CAMERA_TYPES:
            raise ValueError(
                f"camera.type: unknown camera type {self.type!r}; expected one of {CAMERA_TYPES}"
            )
        if not self.name or "/" in self.name or "." in self.name:
            raise ValueError(f"camera.name: {self.name!r} must be a non-empty name without '/' or '.'")
        for key in ("width", "height", "fps"):
            if int(getattr(self, key)) <= 0:
                raise ValueError(f"camera.{key} must be > 0, got {getattr(self, key)}")
        if not 0.0 < self.fovy_deg < 180.0:
            raise ValueError(f"camera.fovy_deg must be in (0, 180), got {self.fovy_deg}")
        if not 0.0 <= self.depth_min_m < self.depth_max_m:
            raise ValueError(
                f"camera.depth_min_m/depth_max_m: need 0 <= min < max, got {self.depth_min_m}, {self.depth_max_m}"
            )
        if self.depth_max_m * 1000.0 > 65535:
            raise ValueError(f"camera.depth_max_m: {self.depth_max_m} m does not fit uint16 millimetres")
        for key in ("pos", "lookat"):
            if len(getattr(self, key)) != 3:
                raise ValueError(f"camera.{key} must have 3 numbers, got {getattr(self, key)}")
        if int(self.supersample) < 1:
            raise ValueError(f"camera.supersample must be >= 1, got {self.supersample}")
        if self.type == "intelrealsense" and self.supersample != 1:
            raise ValueError(
                "camera.supersample is a simulation render option: it must be 1 for 'intelrealsense'"
            )
        if self.type == "intelrealsense" and not self.serial_number_or_name:
            raise ValueError("camera.serial_number_or_name is required for type 'intelrealsense'")

    def to_lerobot_camera_config(self):
        """LeRobot's ``RealSenseCameraConfig`` for the real camera this config describes."""
        if self.type != "intelrealsense":
            raise ValueError(f"camera.type is {self.type!r}; only 'intelrealsense' maps to a LeRobot camera")
        from lerobot.cameras.realsense import RealSenseCameraConfig

        return RealSenseCameraConfig(
            serial_number_or_name=self.serial_number_or_name,
            fps=self.fps,
            width=self.width,
            height=self.height,
            use_depth=self.use_depth,
        )


@dataclass
class EndEffectorConfig:
    """Cartesian end-effector control: action in [-1, 1]^3 times the step sizes, target clipped to bounds."""

    end_effector_bounds: dict[str, list[float]] = field(
        default_factory=lambda: {"min": [-0.3, -0.3, 0.85], "max": [0.3, 0.3, 1.25]}
    )
    end_effector_step_sizes: dict[str, float] = field(
        default_factory=lambda: {"x": 0.05, "y": 0.05, "z": 0.05}
    )
    # Largest displacement per axis and step (the paper's real Sawyer: 0.05 m).
    max_ee_step_m: float = 0.05

    def __post_init__(self):
        bounds = self.end_effector_bounds
        if set(bounds) != {"min", "max"}:
            raise ValueError(
                f"end_effector.end_effector_bounds needs exactly keys min and max, got {sorted(bounds)}"
            )
        for key in ("min", "max"):
            if len(bounds[key]) != 3:
                raise ValueError(
                    f"end_effector.end_effector_bounds.{key} must have 3 numbers, got {bounds[key]}"
                )
        for axis, lo, hi in zip(AXES, bounds["min"], bounds["max"], strict=True):
            if not lo < hi:
                raise ValueError(
                    f"end_effector.end_effector_bounds: min {axis}={lo} must be < max {axis}={hi}"
                )
        steps = self.end_effector_step_sizes
        if set(steps) != set(AXES):
            raise ValueError(f"end_effector.end_effector_step_sizes needs keys x, y, z, got {sorted(steps)}")
        if self.max_ee_step_m <= 0:
            raise ValueError(f"end_effector.max_ee_step_m must be > 0, got {self.max_ee_step_m}")
        for axis in AXES:
            if not 0 < steps[axis] <= self.max_ee_step_m:
                raise ValueError(
                    f"end_effector.end_effector_step_sizes.{axis} must be in (0, max_ee_step_m="
                    f"{self.max_ee_step_m}], got {steps[axis]}"
                )

    @property
    def low(self) -> list[float]:
        return [float(v) for v in self.end_effector_bounds["min"]]

    @property
    def high(self) -> list[float]:
        return [float(v) for v in self.end_effector_bounds["max"]]

    @property
    def step_sizes(self) -> list[float]:
        return [float(self.end_effector_step_sizes[a]) for a in AXES]
