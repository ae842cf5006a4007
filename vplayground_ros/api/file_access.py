"""Files named in requests (~/load_scene, ~/save_scene): confined to the scene directories,
symbolic links and `..` resolved first; written without replacing anything unless asked, and
then atomically.
"""
import os
import time
from pathlib import Path

from ..physics import specs
from ..resources import find_shared
from ..scene import DESCRIPTION_FILE, resolve_mesh
from .results import FAILED, RequestError

MAX_PATH = 4096  # characters of a scene path (PATH_MAX)
MAX_NAME = 255   # bytes of one of its names (NAME_MAX): the system refuses longer ones
SCENE_SUFFIXES = (".yaml", ".yml")  # ~/save_scene with overwrite never replaces anything else


def default_scene_directories(bag_directory=None, scene_file=None):
    """The package's config/, the current working directory, the bag's directory, and the
    folder of the scene the node started with (whose meshes a scene saved from it names)."""
    config = find_shared("config/default_scene.yaml")
    directories = [config.parent] if config is not None else []
    directories.append(Path.cwd())
    for directory in (bag_directory, Path(scene_file).parent if scene_file else None):
        if directory is not None:
            directories.append(Path(directory))
    return directories


def allowed_directories(directories):
    """The scene directories resolved (symbolic links, `..`), the ones that exist."""
    roots = []
    for directory in list(directories):
        try:
            root = Path(directory).resolve()
        except (OSError, ValueError, RuntimeError):
            continue
        if root.is_dir():
            roots.append(root)
    return roots


def local_path(uri):
    """A path given as a file:// URI (simulation_interfaces' resources), or as a path, as a path."""
    return uri[len("file://"):] if uri.startswith("file://") else uri


def confine(raw, what, directories, suffixes=SCENE_SUFFIXES, kind="scene files"):
    """The absolute, resolved path of a file named in a request (a scene file, unless `suffixes`
    and `kind` say otherwise), refused (FAILED) unless it lies inside one of `directories` and
    ends in one of `suffixes`. Relative paths start from the current working directory, as on
    the command line."""
    if not isinstance(raw, str) or not raw:
        raise RequestError(FAILED, f"{what}: the path is missing")
    if len(raw) > MAX_PATH or "\0" in raw:
        raise RequestError(FAILED, f"{what}: {specs.quote(raw)} is not a usable path")
    try:
        resolved = (Path.cwd() / raw).resolve()
    except (OSError, ValueError, RuntimeError) as error:  # too long, unencodable, a link loop
        raise RequestError(FAILED, f"{what}: cannot resolve {specs.quote(raw)}: {error}") from None
    if any(len(os.fsencode(name)) > MAX_NAME for name in resolved.parts):
        raise RequestError(FAILED, f"{what}: {specs.quote(raw)}: a name in it is longer than {MAX_NAME} bytes")
    roots = allowed_directories(directories)
    if not any(resolved.is_relative_to(root) for root in roots):
        raise RequestError(FAILED, f"{what}: {specs.quote(raw)} resolves to {specs.quote(str(resolved))}, "
                                   f"outside the scene directories ({', '.join(map(str, roots)) or 'none'}; "
                                   "the scene_directories parameter)")
    if resolved.suffix.lower() not in suffixes:
        raise RequestError(FAILED, f"{what}: {specs.quote(raw)}: {kind} end in {' or '.join(suffixes)}")
    return resolved


def find_description(name, directories, key):
    """The file of a robot description a request names (~/spawn's `urdf`, SpawnEntity's `uri`),
    found as a scene's robot is (scene.resolve_mesh): absolute, else from the working directory,
    inside `directories` (the scene directories), else the package's config/ (`car.urdf` is the
    built-in car's; never a name with `..`). MissingMesh, naming `key`, where it looked."""
    return resolve_mesh(name, Path.cwd(), directories, key, "config", DESCRIPTION_FILE)


def write_file(target, data, overwrite):
    """Writes `data` to `target`: without overwrite, only if nothing is there (O_EXCL, so not
    even a file or link made since the check is replaced); with it, through a temporary file
    renamed over the old one, so a full disk leaves the old file whole."""
    if not overwrite:
        try:
            with open(target, "xb") as stream:
                stream.write(data)
        except FileExistsError:
            raise
        except OSError:
            target.unlink(missing_ok=True)
            raise
        return
    temporary = target.with_name(f".{target.name}.{os.getpid()}.{time.monotonic_ns()}.tmp")
    try:
        with open(temporary, "xb") as stream:
            stream.write(data)
        os.replace(temporary, target)
    finally:
        temporary.unlink(missing_ok=True)

