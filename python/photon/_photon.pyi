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
        """Simulate the scene and return a Result.

        Arguments left None take the scene's `[simulation]` values, as `photon run` does.
        photons is an int (or an integral float such as 1e6), at least 1; seed 0..2**64-1;
        threads 1..1024 (results never depend on it); rel_error and time positive numbers
        (stop at that relative standard error of every tallied surface, or those in `tally`,
        or after that many seconds); max_bounces 0..2**32-1. Out-of-range values raise
        ValueError naming the argument. Same scene, seed and photons give the CLI's numbers bit
        for bit. The GIL is released while photons are traced. Ctrl-C stops at the next batch
        and raises RunInterrupted, whose `result` holds the batches traced (None if no Result
        could be made of them). progress=True draws a bar (tqdm's when installed).
        """
    def info(self) -> Dict[str, Any]:
        """What `photon info` prints, as a dict."""
    def describe(self) -> str:
        """The text of `photon info`."""
    def to_dict(self) -> Dict[str, Any]:
        """The scene file as nested dicts and lists."""
    def with_overrides(self, overrides: Mapping[str, Any]) -> "Scene":
        """A new Scene with some values replaced, given as {dotted key: value}.

        Keys follow the scene file ("simulation.photons", "materials.white.reflectance"); a
        step into an array of tables (surfaces, lights, detectors) picks the entry by name or
        index ("surfaces.0.material"). A value None removes the key (or the entry); missing
        tables are created; values may be nested mappings and lists. Relative file paths keep
        resolving against the original scene's folder. A key naming no entry raises KeyError.
        """

class Result:
    """What Scene.run returns: tallies, ledger, run info and arrays."""

    @property
    def flux(self) -> List[Dict[str, Any]]: ...
    @property
    def media(self) -> List[Dict[str, Any]]: ...
    @property
    def planes(self) -> List[Dict[str, Any]]: ...
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
        """Write exactly the files `photon run --out dir` writes; returns their names.

        The files are staged in a hidden folder and moved into place whole; files an earlier
        run there listed and this one does not write are removed, nothing else is touched.
        run_info["files"] is set to the list. The GIL is released while writing, and several
        threads may save at once. A folder that cannot be written raises ValueError.
        """
    def summary(self) -> str:
        """The table `photon run` prints."""

def load(path: _Path) -> Scene:
    """Load and check a scene file (TOML).

    Bad input raises SceneError naming the file, key and line. Relative file paths in the scene
    (meshes, spectra, IES files) resolve against its folder, also in later with_overrides after
    a change of the current directory.
    """

def loads(toml_text: str, base_dir: _Path = ".", name: str = "scene") -> Scene:
    """Load a scene from TOML text.

    Relative file paths in it resolve against base_dir; the scene's path is base_dir/name.toml
    (its name in run.json, plot titles and messages). name must be a file name's stem: one with
    '/', '\\' or '..' raises ValueError.
    """

def from_dict(scene: Mapping[str, Any], base_dir: _Path = ".", name: str = "scene") -> Scene:
    """Make a scene from nested mappings and lists in the scene file's layout (Scene.to_dict).

    base_dir and name as for loads. TOML has no null: a key whose value is None is left out, as
    if absent; None inside a list raises TypeError. Nesting deeper than 64 levels (a dict that
    contains itself) raises ValueError.
    """

def validate(quick: bool = True, threads: Optional[int] = None, verbose: bool = False) -> Dict[str, Any]:
    """Run the built-in closed-form validation cases (what `photon validate` runs).

    Returns {"passed": bool, "complete": bool, "cases": [dict per case]}. quick=True takes
    about 10 s on 2 cores; verbose=True prints each case's line as it finishes. Ctrl-C raises
    RunInterrupted (its result None).
    """
