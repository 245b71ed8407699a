"""The table's truth for a motion profile, computed once and cached on disk.

The realised motion of the platform does not depend on the gyro layout: it
is computed once per (profile content, sample rate, duration, table
parameters, physics step, MuJoCo version, schema version) and projected on
any layout's sensitive axes, ``project(truth, layout) = ω_body Hᵀ`` — a sweep
over layouts runs the physics once per profile. The specific force is kept
the same way: MuJoCo's accelerometer at the platform origin (f_0) and the
angular acceleration α, from which :func:`specific_force` gives the force at
any gyro position r by rigid-body kinematics, f = f_0 + α × r + ω × (ω × r)
(the same numbers as MuJoCo accelerometers at the sites, to rounding:
tests/test_specific_force.py).

Schema 2 (this version) added ``specific_force_m_s2`` and
``angular_accel_rad_s2`` and moved gravity to g0 = 9.80665 m/s²; schema-1
files are not read (their key differs), the motion itself is unchanged.

The cache is a folder of ``.npz`` files named by the SHA-256 of that key
(folder: environment variable ``GYROARRAY_CACHE``, default
``~/.cache/gyroarray/truth``). Files are written to a temporary file and
renamed (``os.replace``), read with ``allow_pickle=False``, and checked; an
unreadable, partial or mismatching file is ignored and recomputed.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np

from gyroarray.core.errors import InputError

from gyroarray.sim.profiles import Profile, load_profile
from gyroarray.core.sensor import rigid_body_specific_force
from gyroarray.sim.table import RateTable, TableParams, Tracking, n_samples, rotation_matrices

__all__ = ["TRUTH_SCHEMA_VERSION", "Truth", "TruthMeta", "compute_truth", "project",
           "specific_force", "truth_key", "default_cache_dir"]

#: Bump when the meaning or layout of cached truth changes.
TRUTH_SCHEMA_VERSION = 2

_ARRAYS = ("time_s", "omega_body_rad_s", "quat_wxyz", "command_body_rad_s", "joint_angles_rad",
           "specific_force_m_s2", "angular_accel_rad_s2")


@dataclass(frozen=True)
class TruthMeta:
    """Where a truth came from.

    Parameters
    ----------
    key : str
        Cache key (SHA-256 hex of everything below).
    profile_fingerprint : str
        Content hash of the profile (TOML and CSV bytes).
    profile_source : str or None
        File the profile was read from.
    sample_rate_hz : float
        Sample rate fs [Hz].
    duration_s : float
        Duration run [s].
    physics_dt_s : float
        Physics step [s].
    steps_per_sample : int
        Physics steps per sample [-].
    mujoco_version : str
    schema_version : int
    table : TableParams
    """

    key: str
    profile_fingerprint: str
    profile_source: str | None
    sample_rate_hz: float
    duration_s: float
    physics_dt_s: float
    steps_per_sample: int
    mujoco_version: str
    schema_version: int
    table: TableParams


@dataclass(frozen=True, eq=False)
class Truth:
    """The realised motion of the platform at the gyro sample times.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times ``k / fs`` [s].
    omega_body_rad_s : ndarray, shape (n, 3)
        Platform angular velocity relative to the local-level frame (the
        Earth, as the table's encoders report), in the platform frame, read
        from MuJoCo's reference gyro [rad/s].
    quat_wxyz : ndarray, shape (n, 4)
        Platform attitude, platform -> local level, (w, x, y, z) [-].
    command_body_rad_s : ndarray, shape (n, 3)
        Commanded body rate [rad/s].
    joint_angles_rad : ndarray, shape (n, 3)
        Gimbal encoders (outer, middle, inner) [rad].
    specific_force_m_s2 : ndarray, shape (n, 3)
        Specific force at the platform origin, platform frame, from MuJoCo's
        accelerometer there [m/s²] (+g0 on z at rest, level, z up).
    angular_accel_rad_s2 : ndarray, shape (n, 3)
        Angular acceleration of the platform, dω_body/dt, platform frame,
        from MuJoCo's ``frameangacc`` [rad/s²].
    tracking : Tracking
        Realised vs commanded.
    meta : TruthMeta

    All arrays are read-only.
    """

    time_s: np.ndarray
    omega_body_rad_s: np.ndarray
    quat_wxyz: np.ndarray
    command_body_rad_s: np.ndarray
    joint_angles_rad: np.ndarray
    specific_force_m_s2: np.ndarray
    angular_accel_rad_s2: np.ndarray
    tracking: Tracking
    meta: TruthMeta

    def __post_init__(self):
        for name in _ARRAYS:
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def n_samples(self) -> int:
        """Number of samples n."""
        return int(self.time_s.shape[0])

    @property
    def sample_rate_hz(self) -> float:
        """Sample rate fs [Hz]."""
        return self.meta.sample_rate_hz

    @property
    def rotation_matrices(self) -> np.ndarray:
        """Attitude as rotation matrices, platform -> local level, shape (n, 3, 3) [-]."""
        return rotation_matrices(self.quat_wxyz)


def project(truth: Truth, layout) -> np.ndarray:
    """True rate along each gyro's sensitive axis, ``ω_body Hᵀ``.

    Parameters
    ----------
    truth : Truth
    layout : gyroarray.core.layout.Layout
        Sensitive axes ``H`` (N, 3) in the platform frame.

    Returns
    -------
    ndarray, shape (n, N)
        [rad/s].
    """
    return truth.omega_body_rad_s @ np.asarray(layout.H, dtype=float).T


def specific_force(truth: Truth, positions_m) -> np.ndarray:
    """Specific force at points of the platform, platform frame.

    Parameters
    ----------
    truth : Truth
    positions_m : array_like, shape (N, 3), or a Layout
        Points r_k in the platform frame [m] (a layout's ``positions_m``,
        zero when it has none).

    Returns
    -------
    ndarray, shape (n, N, 3)
        f_k = f_0 + α × r_k + ω × (ω × r_k) [m/s²].
    """
    if hasattr(positions_m, "positions_or_zero"):
        positions_m = positions_m.positions_or_zero
    return rigid_body_specific_force(truth.specific_force_m_s2, truth.omega_body_rad_s,
                                     truth.angular_accel_rad_s2, positions_m)


def default_cache_dir() -> Path:
    """``$GYROARRAY_CACHE`` or ``~/.cache/gyroarray/truth``."""
    env = os.environ.get("GYROARRAY_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "gyroarray" / "truth"


def _key_fields(profile: Profile, fs: float, duration_s: float, table: TableParams) -> dict:
    dt, k = RateTable(table).timestep(fs)
    return {
        "schema": TRUTH_SCHEMA_VERSION,
        "profile": profile.fingerprint,
        "sample_rate_hz": float(fs).hex(),
        "duration_s": float(duration_s).hex(),
        "physics_dt_s": float(dt).hex(),
        "steps_per_sample": k,
        "table": json.loads(json.dumps(asdict(table))),
        "mujoco": mujoco.__version__,
    }


def truth_key(profile, sample_rate_hz: float, *, duration_s: float | None = None,
              table: TableParams | None = None) -> str:
    """The cache key of a truth (SHA-256 hex).

    Parameters
    ----------
    profile : Profile or path
    sample_rate_hz : float
        [Hz]
    duration_s : float, optional
        [s]; default the profile's duration.
    table : TableParams, optional

    Returns
    -------
    str
    """
    profile = profile if isinstance(profile, Profile) else load_profile(profile)
    table = TableParams() if table is None else table
    T = profile.duration_s if duration_s is None else float(duration_s)
    text = json.dumps(_key_fields(profile, float(sample_rate_hz), T, table), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _run_table(profile: Profile, fs: float, duration_s: float, table: TableParams):
    """The physics (monkeypatched by the cache tests to count calls)."""
    return RateTable(table).run(profile, fs, duration_s=duration_s)


def compute_truth(profile, sample_rate_hz: float, *, duration_s: float | None = None,
                  table: TableParams | None = None, cache: bool = True,
                  cache_dir=None) -> Truth:
    """The realised platform motion for a profile, from the cache or from MuJoCo.

    Parameters
    ----------
    profile : Profile or path
        Motion profile (a path is read with ``load_profile``).
    sample_rate_hz : float
        Gyro sample rate fs [Hz].
    duration_s : float, optional
        Run only the first ``duration_s`` of the profile [s].
    table : TableParams, optional
        Table mechanics and servo; default ``TableParams()``.
    cache : bool
        Read and write the on-disk cache.
    cache_dir : str or Path, optional
        Cache folder; default :func:`default_cache_dir`.

    Returns
    -------
    Truth
    """
    profile = profile if isinstance(profile, Profile) else load_profile(profile)
    table = TableParams() if table is None else table
    fs = float(sample_rate_hz)
    T = profile.duration_s if duration_s is None else float(duration_s)
    if not (np.isfinite(T) and 0 < T <= profile.duration_s * (1 + 1e-12)):
        raise InputError(f"duration must be in (0, {profile.duration_s:g}] s, got {duration_s!r}",
                         file=profile.source)
    fields = _key_fields(profile, fs, T, table)
    key = hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = folder / f"{key}.npz"
    meta = TruthMeta(key=key, profile_fingerprint=profile.fingerprint,
                     profile_source=profile.source, sample_rate_hz=fs, duration_s=T,
                     physics_dt_s=float.fromhex(fields["physics_dt_s"]),
                     steps_per_sample=fields["steps_per_sample"],
                     mujoco_version=mujoco.__version__, schema_version=TRUTH_SCHEMA_VERSION,
                     table=table)
    if cache:
        hit = _read(path, meta, n_samples(T, fs))
        if hit is not None:
            return hit
    run = _run_table(profile, fs, T, table)
    truth = Truth(time_s=run.time_s, omega_body_rad_s=run.omega_body_rad_s,
                  quat_wxyz=run.quat_wxyz, command_body_rad_s=run.command_body_rad_s,
                  joint_angles_rad=run.joint_angles_rad,
                  specific_force_m_s2=run.specific_force_m_s2,
                  angular_accel_rad_s2=run.angular_accel_rad_s2, tracking=run.tracking, meta=meta)
    if cache:
        _write(path, truth)
    return truth


def _read(path: Path, meta: TruthMeta, n: int) -> Truth | None:
    """A cached truth, or None when missing, unreadable or not the one asked for."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            header = json.loads(str(z["meta"][()]))
            if header.get("key") != meta.key or header.get("schema") != TRUTH_SCHEMA_VERSION:
                return None
            arrays = {name: np.array(z[name], dtype=float) for name in _ARRAYS}
        shapes = {"time_s": (n,), "omega_body_rad_s": (n, 3), "quat_wxyz": (n, 4),
                  "command_body_rad_s": (n, 3), "joint_angles_rad": (n, 3),
                  "specific_force_m_s2": (n, 3), "angular_accel_rad_s2": (n, 3)}
        if any(arrays[k].shape != s for k, s in shapes.items()):
            return None
        if not all(np.all(np.isfinite(a)) for a in arrays.values()):
            return None
        tracking = Tracking.from_dict(header["tracking"])
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None
    return Truth(**arrays, tracking=tracking, meta=meta)


def _write(path: Path, truth: Truth) -> None:
    """Write atomically (temporary file + os.replace); warn, do not fail, if impossible."""
    header = json.dumps({"key": truth.meta.key, "schema": TRUTH_SCHEMA_VERSION,
                         "profile_source": truth.meta.profile_source,
                         "sample_rate_hz": truth.meta.sample_rate_hz,
                         "duration_s": truth.meta.duration_s,
                         "mujoco": truth.meta.mujoco_version,
                         "tracking": truth.tracking.to_dict()})
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        from gyroarray.core.outputs import remove_stale_temps, temp_prefix  # deferred: a cache write
        remove_stale_temps(path.parent, once=True)     # left by a SIGKILLed writer (its pid gone)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=temp_prefix("." + path.stem[:16]), suffix=".tmp")
        os.chmod(tmp, 0o644)
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, meta=np.array(header),
                                **{name: getattr(truth, name) for name in _ARRAYS})
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        tmp = None
    except OSError as e:
        warnings.warn(f"truth cache not written to {path.parent}: {e}", RuntimeWarning,
                      stacklevel=3)
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
