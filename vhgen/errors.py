"""Error classes. Every error that comes from user input names where it came from."""

from __future__ import annotations

from pathlib import Path


class VhgenError(Exception):
    """Base class of every error vhgen raises on purpose."""


class BVHError(VhgenError):
    """A BVH file that does not follow the grammar, with the file and line at fault."""

    def __init__(self, path: str | Path | None, line: int | None, message: str):
        self.path = None if path is None else str(path)
        self.line = line
        self.message = message
        where = self.path or "<string>"
        if line is not None:
            where = f"{where}:{line}"
        super().__init__(f"{where}: {message}")


class ConfigError(VhgenError):
    """A configuration value that is missing, unknown or out of range; names file and field."""

    def __init__(self, source: str | Path | None, field: str, message: str):
        self.source = None if source is None else str(source)
        self.field = field
        self.message = message
        prefix = f"{self.source}: " if self.source else ""
        super().__init__(f"{prefix}{field}: {message}")


class AssetError(VhgenError):
    """MakeHuman/MPFB2 assets missing or damaged; says which command fetches them."""


class RetargetError(VhgenError):
    """A skeleton that the retarget map cannot handle (unmapped or missing joints)."""


class RenderError(VhgenError):
    """OpenGL context or rendering failure (backend missing, GL error)."""


class StoreError(VhgenError):
    """A dataset store that does not follow the vhgen contract."""


class ShardError(StoreError):
    """A shard of a store's array that cannot be read (missing, truncated, checksum or
    decode failure); names the store, the array, the shard and its frames."""

    def __init__(self, store: str | Path, array: str, shard: int, frames: tuple[int, int],
                 message: str):
        self.store = str(store)
        self.array = array
        self.shard = shard
        self.frames = frames
        self.message = message
        super().__init__(f"{self.store}: {array} shard {shard} (frames {frames[0]}-"
                         f"{frames[1]}): {message}")


class ForestError(VhgenError):
    """A forest file, training set or forest command argument that cannot be used."""


class DepthFileError(VhgenError):
    """A depth file (PCD, PNG) that cannot be read as a depth image; names the file."""

    def __init__(self, path: str | Path, message: str):
        self.path = str(path)
        self.message = message
        super().__init__(f"{self.path}: {message}")


class BackgroundError(VhgenError):
    """A real depth frame that cannot serve as a background (wrong size or intrinsics, no
    floor, no free floor); names the file."""

    def __init__(self, path: str | Path, message: str):
        self.path = str(path)
        self.message = message
        super().__init__(f"{self.path}: {message}")
