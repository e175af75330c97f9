"""A vendor's robot description as it ships: ``package://`` URIs and STL/DAE meshes.

Drake resolves ``package://NAME/...`` through a :class:`pydrake.multibody.parsing.PackageMap`.
:func:`populate_package_map` fills it from the sources a user has: an explicit name ->
folder map, folders searched for ``package.xml`` files, and the ``package.xml`` of the
ROS package the model file sits in (found by walking up from the file).

Drake cannot load STL or DAE meshes (it fails while building collision hulls, and its
renderer ignores them). :func:`drake_loadable_model` converts such meshes once to OBJ
(:mod:`drake_tracker.robot.mesh_cache`) and writes a copy of the model file whose mesh
references point at the converted files; every other byte of the vendor's file is kept,
and the vendor's folder is never written to. URDF ``<mesh filename>``, SDF ``<mesh><uri>``
and the ``file:`` entries of Drake model directives (``.dmd.yaml``, followed
recursively) are rewritten. SDF ``<include>`` is not followed: to combine a vendor's
URDF with other models, use model directives.
"""

import hashlib
import re
from pathlib import Path

from pydrake.multibody.parsing import PackageMap

from drake_tracker.robot.mesh_cache import convert_to_obj, default_cache_dir, needs_conversion

#: URI schemes resolved through the package map.
PACKAGE_SCHEMES = ("package://", "model://")
#: ``<mesh ... filename="...">`` in a URDF.
_URDF_MESH = re.compile(r"(<mesh\b[^>]*?\bfilename\s*=\s*)([\"'])(.*?)\2", re.DOTALL)
#: ``<uri>...</uri>`` inside ``<mesh>...</mesh>`` in an SDF.
_SDF_MESH_URI = re.compile(r"(<mesh\b(?:(?!</mesh>).)*?<uri>\s*)(.*?)(\s*</uri>)", re.DOTALL)
#: ``file: URI`` of ``add_model`` and ``add_directives`` in model directives.
_DIRECTIVE_FILE = re.compile(r"(\bfile:[ \t]*)([\"']?)([^\"'\s#]+)\2")


def populate_package_map(package_map: PackageMap, package_paths: dict[str, str],
                         package_folders: list[str], model_path: Path | None) -> None:
    """Adds packages to ``package_map``: ``package_paths`` (name -> folder), every
    ``package.xml`` under ``package_folders``, and the nearest ``package.xml`` at or above
    ``model_path``'s folder. Names already in the map keep their folder."""
    for name, folder in package_paths.items():
        path = Path(folder).expanduser()
        if not path.is_dir():
            raise ValueError(f"RobotConfig.package_paths: folder '{folder}' of package "
                             f"'{name}' does not exist")
        _add_new(package_map, name, str(path.resolve()))
    for folder in package_folders:
        path = Path(folder).expanduser()
        if not path.is_dir():
            raise ValueError(f"RobotConfig.package_folders: folder '{folder}' does not exist")
        found = PackageMap.MakeEmpty()
        found.PopulateFromFolder(str(path.resolve()))
        _merge(package_map, found)
    if model_path is not None:
        for parent in Path(model_path).resolve().parents:
            if (parent / "package.xml").is_file():
                found = PackageMap.MakeEmpty()
                found.AddPackageXml(str(parent / "package.xml"))
                _merge(package_map, found)
                break


def _add_new(package_map: PackageMap, name: str, folder: str) -> None:
    if not package_map.Contains(name):
        package_map.Add(name, folder)


def _merge(package_map: PackageMap, other: PackageMap) -> None:
    for name in other.GetPackageNames():
        _add_new(package_map, name, other.GetPath(name))


def resolve_uri(uri: str, package_map: PackageMap, base_dir: Path) -> Path:
    """The file a model's ``uri`` names: ``package://`` or ``model://`` through
    ``package_map``, ``file://``, an absolute path, or a path relative to ``base_dir``."""
    uri = uri.strip()
    for scheme in PACKAGE_SCHEMES:
        if uri.startswith(scheme):
            name, _, rest = uri[len(scheme):].partition("/")
            if not package_map.Contains(name):
                raise ValueError(
                    f"'{uri}': package '{name}' is unknown; known packages: "
                    f"{sorted(package_map.GetPackageNames())}. Give its folder in "
                    f"RobotConfig.package_paths or a folder of package.xml files in "
                    f"RobotConfig.package_folders")
            return Path(package_map.GetPath(name)) / rest
    if uri.startswith("file://"):
        return Path(uri[len("file://"):])
    path = Path(uri).expanduser()
    return path if path.is_absolute() else Path(base_dir) / path


def _loadable_mesh_uri(uri: str, package_map: PackageMap, base_dir: Path,
                       cache_dir: Path) -> str:
    """The reference a rewritten copy uses: a converted OBJ, an absolute path for a
    relative reference, or ``uri`` unchanged."""
    path = resolve_uri(uri, package_map, base_dir)
    if needs_conversion(path):
        return convert_to_obj(path, cache_dir).resolve().as_posix()
    if uri.strip().startswith(PACKAGE_SCHEMES + ("file://",)):
        return uri
    return path.resolve().as_posix()


def _write_copy(source: Path, text: str, cache_dir: Path) -> Path:
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    target = cache_dir / "models" / f"{source.name.split('.')[0]}-{digest}{_suffixes(source)}"
    target.parent.mkdir(parents=True, exist_ok=True)
    if not target.is_file():
        tmp = target.with_suffix(target.suffix + ".tmp")
        tmp.write_text(text, encoding="utf-8")
        tmp.replace(target)
    return target


def _suffixes(path: Path) -> str:
    return ".dmd.yaml" if path.name.endswith(".dmd.yaml") else path.suffix


def _rewrite_xml(path: Path, pattern: re.Pattern, uri_group: int, package_map: PackageMap,
                 cache_dir: Path) -> Path:
    text = path.read_text(encoding="utf-8")
    base_dir = path.parent
    if not any(needs_conversion(resolve_uri(m.group(uri_group), package_map, base_dir))
               for m in pattern.finditer(text)):
        return path

    def replace(match: re.Match) -> str:
        new_uri = _loadable_mesh_uri(match.group(uri_group), package_map, base_dir, cache_dir)
        groups = list(match.groups())
        groups[uri_group - 1] = new_uri
        if uri_group == 3:  # URDF: keep the quote character on both sides
            return f"{groups[0]}{groups[1]}{new_uri}{groups[1]}"
        return "".join(groups)

    rewritten = pattern.sub(replace, text)
    return path if rewritten == text else _write_copy(path, rewritten, cache_dir)


def _rewrite_directives(path: Path, package_map: PackageMap, cache_dir: Path) -> Path:
    text = path.read_text(encoding="utf-8")
    matches = list(_DIRECTIVE_FILE.finditer(text))
    sources = [resolve_uri(m.group(3), package_map, path.parent) for m in matches]
    loadables = [drake_loadable_model(s, package_map, cache_dir) for s in sources]
    if all(a == b for a, b in zip(sources, loadables, strict=True)):
        return path
    # The copy lives elsewhere: converted and relative references become absolute.
    # (Text substitution keeps YAML tags such as !Rpy that a load/dump would drop.)
    pieces, end = [], 0
    for match, source, loadable in zip(matches, sources, loadables, strict=True):
        uri = match.group(3)
        if loadable != source or not uri.startswith(PACKAGE_SCHEMES):
            uri = "file://" + loadable.resolve().as_posix()
        pieces += [text[end:match.start(3)], uri]
        end = match.end(3)
    return _write_copy(path, "".join(pieces) + text[end:], cache_dir)


def drake_loadable_model(path: str | Path, package_map: PackageMap,
                         cache_dir: str | Path | None = None) -> Path:
    """``path`` itself if Drake can load it as it is, else a rewritten copy in
    ``cache_dir/models`` whose STL/DAE meshes point at OBJ conversions (see the module
    doc). ``package_map`` must already know the model's packages."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"robot model file '{path}' does not exist")
    cache = Path(cache_dir).expanduser() if cache_dir else default_cache_dir()
    suffix = path.suffix.lower()
    if suffix == ".urdf":
        return _rewrite_xml(path, _URDF_MESH, 3, package_map, cache)
    if suffix == ".sdf":
        return _rewrite_xml(path, _SDF_MESH_URI, 2, package_map, cache)
    if path.name.endswith(".dmd.yaml"):
        return _rewrite_directives(path, package_map, cache)
    raise ValueError(f"robot model file '{path}': expected a .urdf, .sdf or .dmd.yaml file")
