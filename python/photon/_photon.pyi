"""Type hints of the native module photon._photon (written in Rust with PyO3)."""

from os import PathLike
from typing import Any, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, PathLike[str]]

class SceneError(ValueError):
    """A bad scene, or a bad file it names: where, and what is wrong."""

    file: str
    key: str
    line: Optional[int]
    message: str

class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a run at a batch boundary; `result` holds what was traced (None for validate)."""

    result: Optional["Result"]

class Scene:
    """A loaded, checked scene; immutable (with_overrides makes a new one)."""

    @property
    def toml(self) -> str: ...
    @property
    def path(self) -> str: ...
    @property
    def name(self) -> str: ...
    def run(
        self,
        photons: Optional[int] = None,
        seed: Optional[int] = None,
        threads: Optional[int] = None,
        rel_error: Optional[float] = None,
        time: Optional[float] = None,
        integrator: Optional[str] = None,
        image: bool = True,
        progress: bool = False,
        tally: Optional[Sequence[str]] = None,
        max_bounces: Optional[int] = None,
        estimator: str = "auto",
        stratified: bool = False,
        hero: bool = True,
    ) -> "Result":
        """Simulate the scene; see help(photon.Scene.run)."""
    def info(self) -> Dict[str, Any]:
        """What `photon info` prints, as a dict."""
    def describe(self) -> str:
        """The text of `photon info`."""
    def to_dict(self) -> Dict[str, Any]:
        """The scene file as nested dicts and lists."""
    def with_overrides(self, overrides: Mapping[str, Any]) -> "Scene":
        """A new Scene with {dotted key: value} replaced (None removes the key)."""

class Result:
    """What Scene.run returns: tallies, ledger, run info and arrays."""

    @property
    def flux(self) -> List[Dict[str, Any]]: ...
    @property
    def media(self) -> List[Dict[str, Any]]: ...
    @property
    def ledger(self) -> Dict[str, float]: ...
    @property
    def flux_json(self) -> Dict[str, Any]: ...
    @property
    def run_info(self) -> Dict[str, Any]: ...
    @property
    def image(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def xyz(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def y(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def y_var(self) -> Optional[npt.NDArray[np.float32]]: ...
    @property
    def maps(self) -> Dict[str, Dict[str, Any]]: ...
    @property
    def farfield(self) -> Dict[str, Dict[str, Any]]: ...
    @property
    def volumes(self) -> Dict[str, Dict[str, Any]]: ...
    @property
    def warnings(self) -> List[str]: ...
    @property
    def interrupted(self) -> bool: ...
    def save(self, dir: _Path) -> List[str]:
        """Write exactly the files `photon run --out dir` writes; returns their names."""
    def summary(self) -> str:
        """The table `photon run` prints."""

def load(path: _Path) -> Scene:
    """Load and check a scene file."""

def loads(toml_text: str, base_dir: _Path = ".", name: str = "scene") -> Scene:
    """Load a scene from TOML text; relative paths resolve against base_dir."""

def from_dict(scene: Mapping[str, Any], base_dir: _Path = ".", name: str = "scene") -> Scene:
    """Make a scene from nested dicts and lists (see Scene.to_dict)."""

def validate(quick: bool = True, threads: Optional[int] = None, verbose: bool = False) -> Dict[str, Any]:
    """Run the built-in closed-form validation cases."""
