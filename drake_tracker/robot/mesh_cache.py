"""Meshes Drake cannot load (STL, DAE, PLY, ...) converted once to OBJ in a cache folder.

Drake 1.51 renders OBJ and glTF meshes and builds convex hulls from OBJ, VTK and glTF,
but rejects STL and DAE, the usual formats of a vendor's robot package; the tracker's
batched renderer reads OBJ only (``core/render/meshes.py``), so every other format is
converted. The conversion
goes through `trimesh <https://trimesh.org>`_ (and ``pycollada`` for DAE), the optional
``meshes`` extra: ``pip install 'drake_tracker[meshes]'``. The OBJ carries vertex
normals (Drake's OBJ reader needs them) and no materials: colours come from the model.

A converted file is named after its source's content hash, so it is written once and
reused by every later load, by any process.
"""

import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

#: Mesh suffixes kept as they are (Drake and the batched renderer both read them).
DRAKE_MESH_SUFFIXES = (".obj",)
#: Bumped when the conversion changes, so that old cache entries are not reused.
CONVERTER_VERSION = 1
#: Environment variable that overrides the default cache folder.
CACHE_DIR_ENV = "DRAKE_TRACKER_MESH_CACHE"


def default_cache_dir() -> Path:
    """``$DRAKE_TRACKER_MESH_CACHE``, else ``$XDG_CACHE_HOME/drake_tracker/meshes``
    (``~/.cache/drake_tracker/meshes``)."""
    if os.environ.get(CACHE_DIR_ENV):
        return Path(os.environ[CACHE_DIR_ENV]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "drake_tracker" / "meshes"


def needs_conversion(path: str | Path) -> bool:
    """Whether Drake cannot load the mesh file ``path`` as it is."""
    return Path(path).suffix.lower() not in DRAKE_MESH_SUFFIXES


def _import_trimesh():
    try:
        import trimesh
    except ImportError as err:
        raise ImportError(
            "converting STL/DAE meshes to OBJ needs the optional mesh library: "
            "pip install 'drake_tracker[meshes]' (trimesh, pycollada)") from err
    return trimesh


def _area_weighted_vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals, the area-weighted sum of the adjacent faces' normals (trimesh
    computes them too, but needs scipy to do it fast)."""
    v = np.asarray(vertices, float)
    f = np.asarray(faces, np.int64)
    face_normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])  # 2 * area
    normals = np.zeros_like(v)
    for corner in range(3):
        np.add.at(normals, f[:, corner], face_normals)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.tile([0.0, 0.0, 1.0], (len(v), 1)),
                     where=length > 0)


def cached_obj_path(source: str | Path, cache_dir: str | Path) -> Path:
    """Where the OBJ conversion of ``source`` lives in ``cache_dir`` (content-addressed)."""
    source = Path(source)
    digest = hashlib.sha256(source.read_bytes())
    digest.update(f"v{CONVERTER_VERSION}".encode())
    return Path(cache_dir) / f"{source.stem}-{digest.hexdigest()[:16]}.obj"


def convert_to_obj(source: str | Path, cache_dir: str | Path | None = None) -> Path:
    """The OBJ version of the mesh file ``source``, converted on first use.

    Raises FileNotFoundError if ``source`` does not exist, ImportError (naming the
    extra to install) without trimesh, and ValueError if the file holds no triangles.
    """
    source = Path(source)
    if not source.is_file():
        raise FileNotFoundError(f"mesh file '{source}' does not exist")
    target = cached_obj_path(source, cache_dir or default_cache_dir())
    if target.is_file():
        return target
    trimesh = _import_trimesh()
    mesh = trimesh.load(str(source), force="mesh")
    if len(getattr(mesh, "faces", ())) == 0:
        raise ValueError(f"mesh file '{source}' holds no triangles")
    mesh.vertex_normals = _area_weighted_vertex_normals(mesh.vertices, mesh.faces)
    text = trimesh.exchange.obj.export_obj(
        mesh, include_normals=True, include_color=False, include_texture=False,
        header=f"converted by drake_tracker from {source.name}")
    target.parent.mkdir(parents=True, exist_ok=True)
    # Write then rename, so that concurrent loaders never read a partial file.
    handle, tmp = tempfile.mkstemp(dir=target.parent, suffix=".obj.tmp")
    with os.fdopen(handle, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, target)
    return target
