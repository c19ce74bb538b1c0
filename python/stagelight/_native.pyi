"""The engine's half of the package (Rust, PyO3). Use the functions of `stagelight`; these
take the command line's arguments as a list of strings and return raw float32 buffers."""

from typing import Any, Dict, List, Optional, Sequence, Tuple

class SceneError(ValueError):
    """A scene file that cannot be read, or asks for what stagelight does not model."""

class RenderError(RuntimeError):
    """A render, reference or comparison that could not run."""

class Scene:
    """A scene loaded and prepared (its acceleration structure built)."""

    @property
    def path(self) -> str: ...
    @property
    def size(self) -> Tuple[int, int]:
        """(width, height) of the rendered image."""
    @property
    def spp(self) -> Optional[int]:
        """The file's sample count (a Mitsuba sensor's sampler), if it gives one."""
    @property
    def max_depth(self) -> Optional[int]:
        """The file's maximum depth (a Mitsuba integrator's max_depth), if it gives one."""
    @property
    def defines(self) -> Dict[str, str]: ...
    @property
    def triangles(self) -> int: ...
    @property
    def emitters(self) -> int: ...
    @property
    def materials(self) -> List[str]:
        """Each material's kind (Diffuse, RoughPlastic, ...), in the scene's order."""
    @property
    def warnings(self) -> List[str]: ...
    @property
    def camera(self) -> Dict[str, Any]: ...
    def graph(self, integrator: str = "pt") -> str:
        """The integrator's graph of systems for this scene, as `stagelight graph` prints it."""

def load(path: str, defines: Sequence[Tuple[str, str]]) -> Scene: ...
def render(scene: Scene, args: List[str]) -> Dict[str, Any]: ...
def reference(scene: Scene, args: List[str]) -> Dict[str, Any]: ...
def compare(scene: Scene, reference: bytes, args: List[str]) -> List[Dict[str, Any]]: ...
def metrics(image: bytes, reference: bytes, width: int, height: int) -> Dict[str, Any]: ...
def read_exr(path: str) -> Tuple[bytearray, int, int]: ...
def write_exr(path: str, image: bytes, width: int, height: int) -> None: ...
def integrators() -> List[Dict[str, Any]]: ...
