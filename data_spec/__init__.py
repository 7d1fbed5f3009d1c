"""data_spec: the contract between the solver (fem_sim) and the trainer (surrogate).

Scene schema (TOML), geometry and shard schemas (HDF5 + XDMF), writers, readers and a validator.
Depends on numpy and h5py only, so it imports under both project interpreters.
"""

from data_spec.geometry import Geometry, read_geometry, write_geometry
from data_spec.material import OgdenMaterial
from data_spec.scene import (
    SCENE_SCHEMA_VERSION,
    Scene,
    SceneError,
    load_scene,
    parse_scene,
)
from data_spec.shards import (
    SHARD_SCHEMA_VERSION,
    Shard,
    SolverStats,
    geometry_path,
    list_shards,
    read_shard,
    shard_path,
    write_shard,
)
from data_spec.solver_settings import SolverSettings
from data_spec.validate import shard_problems, validate_dataset

__all__ = [
    "SCENE_SCHEMA_VERSION", "SHARD_SCHEMA_VERSION", "Geometry", "OgdenMaterial", "Scene",
    "SceneError", "Shard", "SolverSettings", "SolverStats", "geometry_path", "list_shards",
    "load_scene", "parse_scene", "read_geometry", "read_shard", "shard_path", "shard_problems",
    "validate_dataset", "write_geometry", "write_shard",
]
