"""Integrity of a recorded dataset: content hashes of its files, and the checks both trainers run before
LeRobot reads a dataset (docs/dataset_format.md, "Integrity").

Lossless HEVC and parquet carry no checksum of the frames: flipped bytes in a video's ``mdat`` decode without
error into other frames, and since the indicator reward compares frames bit for bit, a corrupted goal or next
frame silently flips rewards. So every commit of the recorder (data/checkpoint.py) writes
:data:`HASHES`: per data, video and episode-metadata file its blake2b-256 hash, size, and which episodes and
keys it holds. :func:`check_dataset` runs once per training run, before any frame is read:

1. ``meta/info.json`` exists (offline, LeRobot would otherwise try the Hub for it) and every goal feature
   has its observation's shape;
2. each file of the loaded episodes matches its recorded hash (read once, streamed); a dataset without
   :data:`HASHES` (recorded elsewhere) is accepted with one info line saying it is not verified;
3. the shapes the data files store are those ``info.json`` gives, and every video opens with the frame
   size ``info.json`` gives (file headers only).

Every failure is one :class:`DatasetError` line naming the file, keys, episodes and shapes involved.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
from huggingface_hub import constants as hf_constants

from lerobot_indicator.data.errors import DatasetError, one_line, one_line_errors
from lerobot_indicator.keys import OBS_PREFIX, goal_key, is_goal_key, is_ground_truth_key

INFO = "meta/info.json"
# Written by every commit of the recorder; what verification compares the files with.
HASHES = "meta/indicator_hashes.json"
ALGORITHM = "blake2b-256"
# Directories whose files are hashed: they are written once (one set per episode) and never rewritten.
HASHED_DIRS = ("videos", "data", "meta/episodes")
EPISODES_META = "meta/episodes"
# LeRobot's bookkeeping columns, in every data file: not named as the keys a file holds.
_INDEX_KEYS = ("timestamp", "frame_index", "episode_index", "index", "task_index")
# Dtypes stored as images or strings, whose shape the parquet schema does not tell.
_UNSHAPED_DTYPES = ("video", "image", "string")


def file_hash(path: Path) -> str:
    """Streamed :data:`ALGORITHM` hex digest of the file at ``path``."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, lambda: hashlib.blake2b(digest_size=32)).hexdigest()


def _video_keys(info: dict) -> list[str]:
    return [k for k, v in info["features"].items() if v["dtype"] == "video"]


def episode_meta_files(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in (Path(root) / EPISODES_META).glob("*/*.parquet"))


def file_contents(base: Path, info: dict, meta_files: Iterable[str]) -> dict[str, dict[str, set]]:
    """``{file: {"episodes": ..., "keys": ...}}`` for the episode-metadata files ``meta_files`` (relative
    to ``base``) and the data and video files their episodes point to."""
    base = Path(base)
    video_keys = _video_keys(info)
    data_keys = [k for k in info["features"] if k not in video_keys and k not in _INDEX_KEYS]
    columns = ["episode_index", "data/chunk_index", "data/file_index"]
    for key in video_keys:
        columns += [f"videos/{key}/chunk_index", f"videos/{key}/file_index"]
    contents: dict[str, dict[str, set]] = {}

    def add(rel: str, episode: int, keys: Iterable[str]) -> None:
        entry = contents.setdefault(rel, {"episodes": set(), "keys": set()})
        entry["episodes"].add(episode)
        entry["keys"].update(keys)

    for rel in meta_files:
        try:
            rows = pq.read_table(base / rel, columns=columns).to_pylist()
        except (OSError, pa.ArrowException) as err:
            raise DatasetError(f"{base / rel}: cannot read the episode metadata ({one_line(err)})") from err
        for row in rows:
            episode = int(row["episode_index"])
            add(rel, episode, ())
            chunk, file = row["data/chunk_index"], row["data/file_index"]
            add(info["data_path"].format(chunk_index=chunk, file_index=file), episode, data_keys)
            for key in video_keys:
                chunk, file = row[f"videos/{key}/chunk_index"], row[f"videos/{key}/file_index"]
                add(
                    info["video_path"].format(video_key=key, chunk_index=chunk, file_index=file),
                    episode,
                    [key],
                )
    return contents


def hash_entries(base: Path, info: dict, files: list[str]) -> dict[str, dict]:
    """:data:`HASHES` entries of ``files`` (relative to ``base``), which hold whole episodes whose
    metadata files are among them."""
    base = Path(base)
    contents = file_contents(base, info, [f for f in files if f.startswith(EPISODES_META + "/")])
    entries = {}
    for rel in files:
        held = contents.get(rel, {"episodes": set(), "keys": set()})
        entries[rel] = {
            "hash": file_hash(base / rel),
            "size": (base / rel).stat().st_size,
            "episodes": sorted(held["episodes"]),
            "keys": sorted(held["keys"]),
        }
    return entries


def read_hashes(root: Path) -> dict | None:
    path = Path(root) / HASHES
    if not path.exists():
        return None
    try:
        hashes = json.loads(path.read_text())
        files = hashes["files"]
    except (json.JSONDecodeError, KeyError, TypeError) as err:
        raise DatasetError(f"{path}: not a hash file ({one_line(err)})") from err
    if hashes.get("algorithm") != ALGORITHM or not isinstance(files, dict):
        raise DatasetError(f"{path}: expected {ALGORITHM} hashes, got algorithm {hashes.get('algorithm')!r}")
    return hashes


def updated_hashes(root: Path, base: Path, info: dict, new_files: list[str]) -> str:
    """:data:`HASHES` text of ``root`` with the entries of ``new_files`` (closed files in ``base``, about to
    be committed to ``root``) added."""
    hashes = read_hashes(root) or {"algorithm": ALGORITHM, "files": {}}
    hashes["files"].update(hash_entries(base, info, new_files))
    files = ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in sorted(hashes["files"].items()))
    return f'{{\n "algorithm": {json.dumps(ALGORITHM)},\n "files": {{\n{files}\n }}\n}}\n'


def _ranges(values: Iterable[int]) -> str:
    """``[0, 1, 2, 5] -> "0-2, 5"``."""
    spans: list[list[int]] = []
    for v in sorted(values):
        if spans and v == spans[-1][1] + 1:
            spans[-1][1] = v
        else:
            spans.append([v, v])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)


def describe(entry: dict) -> str:
    """``"keys observation.images.front; episodes 0-3"`` for a :data:`HASHES` entry or file contents."""
    keys = ", ".join(sorted(entry["keys"])) or "episode metadata"
    return f"keys {keys}; episodes {_ranges(entry['episodes']) or 'none'}"


def verify_hashes(root: Path, episodes: list[int] | None = None) -> int | None:
    """Compare every file :data:`HASHES` lists (only those holding one of ``episodes``, if given, plus the
    episode metadata) with its recorded size and hash. Returns the number of files verified, ``None`` for a
    dataset without :data:`HASHES`. Raises :class:`DatasetError` naming the first mismatching file, its keys
    and episodes (and how many more mismatch)."""
    root = Path(root)
    hashes = read_hashes(root)
    if hashes is None:
        logging.info("%s has no %s: its files are not verified (recorded by another tool)", root, HASHES)
        return None
    wanted = None if episodes is None else set(episodes)
    bad: list[str] = []
    checked = 0
    for rel, entry in hashes["files"].items():
        if wanted is not None and not rel.startswith(EPISODES_META) and not wanted & set(entry["episodes"]):
            continue
        path = root / rel
        if not path.is_file():
            problem = "is missing"
        elif path.stat().st_size != entry["size"]:
            problem = f"has {path.stat().st_size} bytes, {entry['size']} were recorded"
        elif file_hash(path) != entry["hash"]:
            problem = f"does not match its recorded {ALGORITHM} hash"
        else:
            checked += 1
            continue
        bad.append(f"{path} ({describe(entry)}) {problem}")
    listed = set(hashes["files"])
    unlisted = [
        p.relative_to(root).as_posix()
        for d in HASHED_DIRS
        for p in sorted((root / d).rglob("*"))
        if p.is_file() and p.relative_to(root).as_posix() not in listed
    ]
    if unlisted:
        logging.info(
            "%s: %d files are not in %s and not verified (e.g. %s)", root, len(unlisted), HASHES, unlisted[0]
        )
    if bad:
        more = f" ({len(bad) - 1} more files fail too)" if len(bad) > 1 else ""
        raise DatasetError(
            f"{bad[0]}: the file was changed or corrupted after recording{more}; re-record those episodes"
        )
    return checked


def check_goal_shapes(root: Path, features: dict) -> None:
    """Every goal feature has the shape of the observation it is the goal of."""
    for key, feature in features.items():
        if not key.startswith(OBS_PREFIX) or is_goal_key(key) or is_ground_truth_key(key):
            continue
        goal = goal_key(key)
        if goal in features and tuple(features[goal]["shape"]) != tuple(feature["shape"]):
            raise DatasetError(
                f"{Path(root) / INFO}: goal {goal} has shape {tuple(features[goal]['shape'])} but its observation "
                f"{key} has shape {tuple(feature['shape'])}; a goal must have its observation's shape"
            )


def _stored_shape(arrow_type: pa.DataType) -> tuple[int, ...] | None:
    """The value shape a parquet column stores; ``None`` where its schema does not tell (variable lists)."""
    if pa.types.is_fixed_size_list(arrow_type):
        inner = _stored_shape(arrow_type.value_type)
        return None if inner is None else (arrow_type.list_size, *([] if inner == (1,) else inner))
    if pa.types.is_list(arrow_type) or pa.types.is_large_list(arrow_type) or pa.types.is_struct(arrow_type):
        return None
    return (1,)


def check_stored_shapes(root: Path, info: dict, data_files: dict[str, dict]) -> None:
    """The vector features of each data file (parquet schema, footer only) have ``info.json``'s shapes."""
    root = Path(root)
    features = {k: v for k, v in info["features"].items() if v["dtype"] not in _UNSHAPED_DTYPES}
    for rel, held in data_files.items():
        try:
            schema = pq.read_schema(root / rel)
        except (OSError, pa.ArrowException) as err:
            raise DatasetError(
                f"{root / rel} ({describe(held)}): cannot read it as parquet ({one_line(err)})"
            ) from err
        for key, feature in features.items():
            expected = tuple(feature["shape"])
            if key not in schema.names:
                raise DatasetError(
                    f"{root / rel} (episodes {_ranges(held['episodes'])}): no column {key}, which {INFO} lists"
                )
            stored = _stored_shape(schema.field(key).type)
            if stored is not None and stored != expected:
                raise DatasetError(
                    f"{root / rel} (episodes {_ranges(held['episodes'])}): {key} is stored with shape {stored}, "
                    f"{INFO} says {expected}"
                )


def check_videos(root: Path, info: dict, video_files: dict[str, dict]) -> None:
    """Each video opens (container header) with the frame size ``info.json`` gives its key."""
    import av

    root = Path(root)
    for rel, held in video_files.items():
        key = next(iter(held["keys"]))
        height, width = info["features"][key]["shape"][:2]
        try:
            with av.open(str(root / rel)) as container:
                stream = container.streams.video[0]
                size = (stream.codec_context.height, stream.codec_context.width)
        except Exception as err:  # av raises many types (and UnicodeDecodeError) on a damaged container
            raise DatasetError(
                f"{root / rel} ({describe(held)}): cannot be opened as a video ({one_line(err)})"
            ) from err
        if size != (height, width):
            raise DatasetError(
                f"{root / rel} ({describe(held)}): frames are {size[0]}x{size[1]}, {INFO} says {height}x{width}"
            )


def hub_offline() -> bool:
    """HF_HUB_OFFLINE, as huggingface_hub read it at import or as set since."""
    set_now = os.environ.get("HF_HUB_OFFLINE", "").upper() in ("1", "ON", "YES", "TRUE")
    return bool(hf_constants.HF_HUB_OFFLINE) or set_now


def read_info(root: Path) -> dict:
    path = Path(root) / INFO
    if not path.is_file():
        offline = " (offline: HF_HUB_OFFLINE is set, nothing is downloaded)" if hub_offline() else ""
        raise DatasetError(f"no dataset at {root}: {INFO} is missing{offline}")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise DatasetError(f"{path}: not valid JSON ({one_line(err)})") from err


def check_dataset(root: Path, episodes: list[int] | None = None) -> int | None:
    """All checks of the module docstring on the dataset at ``root`` (the episodes ``episodes``, default
    all); returns the number of files whose hashes were verified, ``None`` if it has no :data:`HASHES`."""
    root = Path(root)
    info = read_info(root)
    check_goal_shapes(root, info["features"])
    verified = verify_hashes(root, episodes)
    contents = file_contents(root, info, episode_meta_files(root))
    if episodes is not None:
        contents = {k: v for k, v in contents.items() if set(episodes) & v["episodes"]}
    check_stored_shapes(root, info, {k: v for k, v in contents.items() if k.startswith("data/")})
    check_videos(root, info, {k: v for k, v in contents.items() if k.startswith("videos/")})
    return verified


def check_before_loading(repo_id: str, root: str | Path | None, episodes: list[int] | None = None) -> bool:
    """:func:`check_dataset` on the dataset ``lerobot-train``/``LeRobotDataset`` would load from ``root``
    (default ``$HF_LEROBOT_HOME/<repo_id>``). Returns False, checking nothing, when it is not there and
    LeRobot may download it (online): then check ``dataset.root`` once it is loaded."""
    from lerobot.utils.constants import HF_LEROBOT_HOME

    root = Path(root) if root else HF_LEROBOT_HOME / repo_id
    if not (root / INFO).is_file() and not hub_offline():
        return False
    check_dataset(root, episodes)
    return True


# ---------------- frame reads ----------------


def _locate(dataset: Any, idx: int) -> tuple[int, int, str | None, Path | None, BaseException | None]:
    """(episode, frame index, key, file, error) of the camera frame of row ``idx`` that fails to decode
    on its own; key/file/error ``None`` if none does."""
    import io

    import PIL.Image
    from lerobot.datasets.video_utils import decode_video_frames

    row = dataset.hf_dataset.with_format("arrow")[idx].to_pylist()[0]
    episode, frame = int(row["episode_index"]), int(row["frame_index"])
    meta, root = dataset.meta, Path(dataset.root)
    backend = getattr(dataset, "_video_backend", None) or "pyav"  # LeRobotDataset keeps its backend private
    for key in meta.camera_keys:
        try:
            if key in meta.video_keys:
                path = root / meta.get_video_file_path(episode, key)
                start = meta.episodes[episode][f"videos/{key}/from_timestamp"]
                decode_video_frames(path, [start + row["timestamp"]], dataset.tolerance_s, backend)
            else:
                path = root / meta.get_data_file_path(episode)
                with PIL.Image.open(io.BytesIO(row[key]["bytes"])) as image:
                    image.load()
        except Exception as err:
            return episode, frame, key, path, err
    return episode, frame, None, None, None


def read_frame(dataset: Any, idx: int) -> dict:
    """``dataset[idx]``; a failure is re-raised as one :class:`DatasetError` line naming the key, episode,
    frame index and file."""
    try:
        return dataset[idx]
    except Exception as err:
        try:
            episode, frame, key, path, cause = _locate(dataset, idx)
        except Exception:
            raise DatasetError(f"{dataset.root}: cannot read frame {idx} ({one_line(err)})") from err
        if key is None:
            path = Path(dataset.root) / dataset.meta.get_data_file_path(episode)
            raise DatasetError(
                f"cannot read episode {episode}, frame {frame} from {path} ({one_line(err)})"
            ) from err
        raise DatasetError(
            f"cannot read {key} of episode {episode}, frame {frame} from {path} ({one_line(cause)})"
        ) from err


# ---------------- lerobot-train and the verify CLI ----------------


def _checked_datasets(make: Callable) -> Callable:
    """``make_train_eval_datasets`` of ``lerobot-train`` with :func:`check_dataset` first (or right after a
    download), on the main process only (the other ranks read the same files after it)."""

    @functools.wraps(make)
    def make_checked(cfg: Any) -> Any:
        ds = cfg.dataset
        main_rank = int(os.environ.get("RANK", "0")) == 0
        checkable = main_rank and isinstance(ds.repo_id, str) and not getattr(ds, "streaming", False)
        checked = False
        if checkable:
            with one_line_errors():
                checked = check_before_loading(ds.repo_id, ds.root, ds.episodes)
        if checked:
            fetch_episode_end_only_without_goals(cfg, ds.root or _lerobot_home() / ds.repo_id)
        datasets = make(cfg)
        if checkable and not checked:
            with one_line_errors():
                check_dataset(datasets[0].root, ds.episodes)
        return datasets

    make_checked.checks_integrity = True
    return make_checked


def _lerobot_home() -> Path:
    from lerobot.utils.constants import HF_LEROBOT_HOME

    return Path(HF_LEROBOT_HOME)


def fetch_episode_end_only_without_goals(cfg: Any, root: str | Path) -> None:
    """A policy config whose ``episode_end_goal`` is unset (the indicator policy's) fetches each episode's last
    frame, the stand-in recorded goal, only when the dataset at ``root`` stores no goal: the policy's features
    are set after the dataset is made, so without this every sample of a dataset with goals reads one frame
    more."""
    policy = getattr(cfg, "policy", None)
    if policy is None or getattr(policy, "episode_end_goal", False) is not None:
        return
    policy.episode_end_goal = not any(is_goal_key(k) for k in read_info(Path(root))["features"])


def install_lerobot_train_check() -> bool:
    """In a ``lerobot-train`` process, check the dataset before LeRobot reads it. LeRobot has no hook that
    runs once per run with the dataset root known before the dataset is read (the policy is built after
    it), so this wraps the training script's ``make_train_eval_datasets``: it runs after the config is
    parsed and validated (config errors come first) and sees the parsed ``--dataset.*`` (also from
    ``--config_path``). Returns whether a training script was found."""
    found = False
    for name in ("lerobot.scripts.lerobot_train", "__main__"):
        module = sys.modules.get(name)
        if module is None or not str(getattr(module, "__file__", "")).endswith("lerobot_train.py"):
            continue
        make = getattr(module, "make_train_eval_datasets", None)
        if make is not None and not getattr(make, "checks_integrity", False):
            module.make_train_eval_datasets = _checked_datasets(make)
        found = True
    return found


@dataclass
class VerifyConfig:
    # Dataset id; the dataset is read from root (default $HF_LEROBOT_HOME/<repo_id>), never downloaded.
    repo_id: str | None = None
    root: Path | None = None
    # Episodes to verify (default all).
    episodes: list[int] | None = None


def verify(cfg: VerifyConfig) -> str:
    """The checks of :func:`check_dataset`; returns the line the CLI prints."""
    from lerobot.utils.constants import HF_LEROBOT_HOME

    if not cfg.repo_id and not cfg.root:
        raise DatasetError("give --root=<dataset directory> or --repo_id=<user/name>")
    root = Path(cfg.root) if cfg.root else HF_LEROBOT_HOME / cfg.repo_id
    verified = check_dataset(root, cfg.episodes)
    if verified is None:
        return f"{root}: not verified, it has no {HASHES}; shapes and video headers are as info.json says"
    return f"{root}: {verified} files match their recorded {ALGORITHM} hashes; shapes and video headers are as info.json says"


def main() -> None:
    """``lerobot-indicator-verify --root=<dataset> [--repo_id=...] [--episodes=[...]]``."""
    import draccus
    from lerobot.utils.utils import init_logging

    init_logging()
    cfg = draccus.parse(VerifyConfig)
    with one_line_errors():
        print(verify(cfg), flush=True)


if __name__ == "__main__":
    main()
