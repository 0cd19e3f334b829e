"""Type stubs of the native module `pathgrad._pathgrad` (python/src/lib.rs). Use the wrappers in
`pathgrad` rather than these: they check shapes and dtypes and give keyword defaults."""

from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

class Scene:
    @property
    def source(self) -> str: ...
    @property
    def size(self) -> Tuple[int, int]: ...
    @property
    def warnings(self) -> List[str]: ...
    def param_names(self) -> List[str]: ...
    def param_info(self, name: str) -> Tuple[List[int], Tuple[float, float]]: ...
    def get_param(self, name: str) -> npt.NDArray[np.float32]: ...
    def set_param(self, name: str, values: npt.NDArray[np.float32]) -> None: ...
    def sensors(self) -> List[Dict[str, Any]]: ...
    def sensor_index(self, selector: str) -> int: ...
    def open_backends(self) -> int: ...

def load(
    spec: str,
    defines: Sequence[Tuple[str, str]],
    width: Optional[int] = None,
    height: Optional[int] = None,
    sensor: Optional[str] = None,
    env: Optional[Sequence[float]] = None,
    env_map: Optional[str] = None,
    allow_outside_folder: bool = False,
) -> Scene: ...
def render(
    scene: Scene,
    sensors: Sequence[int],
    spp: Optional[int] = None,
    seed: int = 0,
    device: Optional[str] = None,
    max_depth: Optional[int] = None,
) -> npt.NDArray[np.float32]: ...
def backward(
    scene: Scene,
    adjoint: npt.NDArray[np.float32],
    sensors: Sequence[int],
    wrt: Optional[Sequence[str]] = None,
    spp: Optional[int] = None,
    seed: int = 0,
    device: Optional[str] = None,
    max_depth: Optional[int] = None,
    deterministic: bool = False,
    sampling: str = "detached",
    jacobian_noise: Optional[float] = None,
) -> Dict[str, npt.NDArray[np.float32]]: ...
def loss_and_gradient(
    scene: Scene,
    targets: npt.NDArray[np.float32],
    sensors: Sequence[int],
    loss: str = "relmse",
    wrt: Optional[Sequence[str]] = None,
    spp: Optional[int] = None,
    seed: int = 0,
    device: Optional[str] = None,
    max_depth: Optional[int] = None,
    deterministic: bool = False,
    sampling: str = "detached",
    jacobian_noise: Optional[float] = None,
) -> Tuple[float, Dict[str, npt.NDArray[np.float32]]]: ...
def image_gradient(
    scene: Scene,
    name: str,
    spp: Optional[int] = None,
    seed: int = 0,
    device: Optional[str] = None,
    max_depth: Optional[int] = None,
    sampling: str = "detached",
    jacobian_noise: Optional[float] = None,
) -> npt.NDArray[np.float32]: ...
def read_image(path: str) -> npt.NDArray[np.float32]: ...
def write_image(path: str, width: int, height: int, values: npt.NDArray[np.float32]) -> None: ...
def devices() -> List[Tuple[int, str, str, List[str]]]: ...
def lavapipe_environment() -> List[Tuple[str, str]]: ...
