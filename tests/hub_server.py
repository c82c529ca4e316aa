"""A local stand-in for the Hugging Face Hub HTTP API, for offline upload/download tests.

It speaks the part of the protocol that ``huggingface_hub`` 1.x uses when LeRobot pushes a dataset
(``LeRobotDataset.push_to_hub``) or a policy (``PreTrainedPolicy.push_model_to_hub``) and when it
downloads one back: create repo, ``validate-yaml``, ``preupload`` (always answers ``"regular"``, so no
LFS/Xet transfer is ever needed), NDJSON ``commit`` with base64 inline files, branches, tags, refs,
repo info, tree listing and ``resolve`` downloads. Commits are real (git blob ids, parent chain,
immutable snapshots), so tags and revisions resolve like on the Hub.

Every file of a branch tip is also materialised under ``<root>/<type>s/<namespace>/<name>/`` so
tests can inspect what arrived with plain file reads.
"""

from __future__ import annotations

import base64
import hashlib
import json
import threading
import time
import uuid
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, unquote, urlsplit

import yaml

LOCAL_USER = "local-user"
REPO_TYPES = {"models": "model", "datasets": "dataset", "spaces": "space"}
URL_PREFIX = {"model": "", "dataset": "datasets/", "space": "spaces/"}


def git_blob_oid(content: bytes) -> str:
    """Git's blob id, which is what ``huggingface_hub`` compares to skip unchanged regular files."""
    return hashlib.sha1(b"blob %d\0" % len(content) + content).hexdigest()


def _check_repo_path(path: str) -> None:
    """The Hub refuses paths that leave the repository: absolute ones and any ``..`` segment."""
    if path.startswith("/") or ".." in path.split("/"):
        raise HubError(400, f"Invalid path {path!r}: it must stay inside the repository")


class HubError(Exception):
    def __init__(self, status: int, message: str, error_code: str | None = None, extra: dict | None = None):
        super().__init__(message)
        self.status, self.message, self.error_code = status, message, error_code
        self.extra = extra or {}  # more JSON fields of the error body, as the real Hub sends them


@dataclass
class Commit:
    oid: str
    parent: str | None
    title: str
    files: dict[str, str]  # path -> blob oid


@dataclass
class Repo:
    repo_type: str
    repo_id: str
    private: bool
    commits: dict[str, Commit] = field(default_factory=dict)
    branches: dict[str, str] = field(default_factory=dict)
    tags: dict[str, str] = field(default_factory=dict)

    def resolve(self, revision: str) -> Commit:
        oid = self.branches.get(revision) or self.tags.get(revision)
        if oid is None and revision in self.commits:
            oid = revision
        if oid is None:
            raise HubError(404, f"Invalid rev id: {revision}", "RevisionNotFound")
        return self.commits[oid]


class LocalHub:
    """Repository storage plus an HTTP server thread. Use as a context manager or call start/stop."""

    def __init__(self, root: Path | str, host: str = "127.0.0.1", port: int = 0):
        self.root = Path(root)
        self.blobs_dir = self.root / "blobs"
        self.blobs_dir.mkdir(parents=True, exist_ok=True)
        self.repos: dict[tuple[str, str], Repo] = {}
        self.requests: list[tuple[str, str]] = []  # (method, path) log, for assertions
        self._lock = threading.RLock()
        self._server = ThreadingHTTPServer((host, port), _make_handler(self))
        self._server.daemon_threads = True
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ lifecycle
    @property
    def url(self) -> str:
        host, port = self._server.server_address[:2]
        return f"http://{host}:{port}"

    def start(self) -> LocalHub:
        self._thread = threading.Thread(target=self._server.serve_forever, name="local-hub", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        if self._thread is not None:
            self._thread.join(timeout=5)

    def __enter__(self) -> LocalHub:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ inspection helpers for tests
    def repo(self, repo_id: str, repo_type: str = "dataset") -> Repo:
        try:
            return self.repos[(repo_type, repo_id)]
        except KeyError:
            raise KeyError(f"no {repo_type} repo {repo_id!r} on the local hub") from None

    def files(self, repo_id: str, repo_type: str = "dataset", revision: str = "main") -> dict[str, bytes]:
        """Content of every file at ``revision`` (branch, tag or commit)."""
        commit = self.repo(repo_id, repo_type).resolve(revision)
        return {path: self._read_blob(oid) for path, oid in commit.files.items()}

    def checkout_dir(self, repo_id: str, repo_type: str = "dataset", branch: str = "main") -> Path:
        return self.root / f"{repo_type}s" / repo_id / branch

    # ------------------------------------------------------------------ storage
    def _write_blob(self, content: bytes) -> str:
        oid = git_blob_oid(content)
        path = self.blobs_dir / oid
        if not path.exists():
            tmp = path.with_suffix(f".{uuid.uuid4().hex}.tmp")
            tmp.write_bytes(content)
            tmp.replace(path)
        return oid

    def _read_blob(self, oid: str) -> bytes:
        return (self.blobs_dir / oid).read_bytes()

    def _materialise(self, repo: Repo, branch: str) -> None:
        target = self.checkout_dir(repo.repo_id, repo.repo_type, branch)
        commit = repo.commits[repo.branches[branch]]
        if target.exists():
            for old in sorted(target.rglob("*"), reverse=True):
                old.unlink() if old.is_file() else old.rmdir()
        for path, oid in commit.files.items():
            dest = target / path
            dest.parent.mkdir(parents=True, exist_ok=True)
            dest.write_bytes(self._read_blob(oid))

    def _new_commit(self, repo: Repo, branch: str, title: str, files: dict[str, str]) -> Commit:
        parent = repo.branches.get(branch)
        seed = json.dumps([parent, title, sorted(files.items()), time.time_ns()]).encode()
        commit = Commit(oid=hashlib.sha1(seed).hexdigest(), parent=parent, title=title, files=files)
        repo.commits[commit.oid] = commit
        repo.branches[branch] = commit.oid
        self._materialise(repo, branch)
        return commit

    def get_repo(self, repo_type: str, repo_id: str) -> Repo:
        repo = self.repos.get((repo_type, repo_id))
        if repo is None:
            raise HubError(404, f"Repository not found: {repo_type} {repo_id}", "RepoNotFound")
        return repo

    # ------------------------------------------------------------------ API operations
    def create_repo(self, body: dict) -> dict:
        repo_type = body.get("type") or "model"
        if repo_type not in URL_PREFIX:
            raise HubError(400, f"Invalid repo type {repo_type!r}")
        name = body.get("name")
        if not name or "/" in name:
            raise HubError(400, f"Invalid repo name {name!r}")
        repo_id = f"{body.get('organization') or LOCAL_USER}/{name}"
        url = f"{self.url}/{URL_PREFIX[repo_type]}{repo_id}"
        with self._lock:
            if (repo_type, repo_id) in self.repos:
                # The real Hub's 409 carries the repo url; huggingface_hub's create_repo(exist_ok=True) reads it.
                raise HubError(409, "You already created this repo", None, {"url": url})
            repo = Repo(repo_type, repo_id, private=body.get("visibility") == "private")
            self.repos[(repo_type, repo_id)] = repo
            gitattributes = self._write_blob(b"*.safetensors filter=lfs diff=lfs merge=lfs -text\n")
            self._new_commit(repo, "main", "initial commit", {".gitattributes": gitattributes})
        return {"url": url, "name": repo_id, "id": uuid.uuid4().hex}

    def preupload(self, repo: Repo, revision: str, body: dict) -> dict:
        try:
            existing = repo.resolve(revision).files
        except HubError:
            existing = {}
        return {
            "files": [
                # "regular": the content travels base64-inline in the commit, no LFS/Xet round trip.
                {
                    "path": f["path"],
                    "uploadMode": "regular",
                    "shouldIgnore": False,
                    "oid": existing.get(f["path"]),
                }
                for f in body["files"]
            ]
        }

    def commit(self, repo: Repo, revision: str, ndjson: bytes, create_pr: bool) -> dict:
        if create_pr:
            raise HubError(400, "pull requests are not supported by the local hub")
        lines = [json.loads(line) for line in ndjson.splitlines() if line.strip()]
        if not lines or lines[0].get("key") != "header":
            raise HubError(400, "commit payload must start with a header line")
        header = lines[0]["value"]
        with self._lock:
            if revision not in repo.branches:
                raise HubError(
                    404, f"Invalid rev id: {revision} (commits go to branches)", "RevisionNotFound"
                )
            parent = repo.branches[revision]
            if header.get("parentCommit") not in (None, parent):
                raise HubError(412, "A commit has happened since. Please refresh and try again.")
            files = dict(repo.commits[parent].files)
            for line in lines[1:]:
                key, value = line["key"], line["value"]
                _check_repo_path(value.get("path", ""))
                if key == "file":
                    if value.get("encoding") != "base64":
                        raise HubError(400, f"unsupported encoding {value.get('encoding')!r}")
                    files[value["path"]] = self._write_blob(base64.b64decode(value["content"]))
                elif key == "deletedFile":
                    if files.pop(value["path"], None) is None:
                        raise HubError(404, "A file with this name doesn't exist", "EntryNotFound")
                elif key == "deletedFolder":
                    prefix = value["path"].rstrip("/") + "/"
                    for path in [p for p in files if p.startswith(prefix)]:
                        del files[path]
                else:  # lfsFile / copies: never requested, since preupload always answers "regular"
                    raise HubError(400, f"commit operation {key!r} is not supported by the local hub")
            commit = self._new_commit(repo, revision, header.get("summary", ""), files)
        url = f"{self.url}/{URL_PREFIX[repo.repo_type]}{repo.repo_id}/commit/{commit.oid}"
        return {"success": True, "commitOid": commit.oid, "commitUrl": url, "pullRequestUrl": None}

    def repo_info(self, repo: Repo, revision: str) -> dict:
        commit = repo.resolve(revision)
        return {
            "id": repo.repo_id,
            "_id": repo.repo_id,
            "sha": commit.oid,
            "private": repo.private,
            "disabled": False,
            "gated": False,
            "siblings": [{"rfilename": path} for path in sorted(commit.files)],
            "tags": [],
        }

    def refs(self, repo: Repo) -> dict:
        def fmt(kind: str, refs: dict[str, str]) -> list[dict]:
            return [{"name": n, "ref": f"refs/{kind}/{n}", "targetCommit": oid} for n, oid in refs.items()]

        return {"branches": fmt("heads", repo.branches), "tags": fmt("tags", repo.tags), "converts": []}

    def tree(self, repo: Repo, revision: str, prefix: str, recursive: bool) -> list[dict]:
        commit = repo.resolve(revision)
        prefix = prefix.strip("/")
        base = f"{prefix}/" if prefix else ""
        entries, folders = [], set()
        for path, oid in sorted(commit.files.items()):
            if not path.startswith(base):
                continue
            rest = path[len(base) :]
            parts = rest.split("/")
            for depth in range(1, len(parts) if recursive else min(2, len(parts))):
                folders.add(base + "/".join(parts[:depth]))
            if recursive or len(parts) == 1:
                size = (self.blobs_dir / oid).stat().st_size
                entries.append({"type": "file", "path": path, "oid": oid, "size": size})
        if prefix and not entries and not folders:
            raise HubError(404, f"{prefix} does not exist on {revision}", "EntryNotFound")
        folder_entries = [
            {"type": "directory", "path": p, "oid": git_blob_oid(p.encode()), "size": 0} for p in folders
        ]
        return sorted(folder_entries, key=lambda e: e["path"]) + entries

    def paths_info(self, repo: Repo, revision: str, paths: list[str]) -> list[dict]:
        commit = repo.resolve(revision)
        out = []
        for path in paths:
            if path in commit.files:
                oid = commit.files[path]
                out.append(
                    {"type": "file", "path": path, "oid": oid, "size": (self.blobs_dir / oid).stat().st_size}
                )
        return out

    def create_ref(self, repo: Repo, kind: str, name: str, revision: str) -> None:
        with self._lock:
            refs = repo.tags if kind == "tag" else repo.branches
            if name in refs:
                raise HubError(409, f"{kind} {name!r} already exists")
            refs[name] = repo.resolve(revision).oid
            if kind == "branch":
                self._materialise(repo, name)

    def delete_ref(self, repo: Repo, kind: str, name: str) -> None:
        with self._lock:
            refs = repo.tags if kind == "tag" else repo.branches
            if refs.pop(name, None) is None:
                raise HubError(404, f"Invalid rev id: {name}", "RevisionNotFound")


def validate_card_yaml(content: str) -> None:
    """What the Hub's ``/api/validate-yaml`` enforces that matters here: the front matter is a YAML mapping."""
    if not content.startswith("---"):
        return
    end = content.find("\n---", 3)
    if end < 0:
        raise HubError(400, "README.md metadata block is not closed with '---'")
    try:
        meta = yaml.safe_load(content[3:end])
    except yaml.YAMLError as err:
        raise HubError(400, f"Invalid YAML in README.md metadata: {err}") from err
    if meta is not None and not isinstance(meta, dict):
        raise HubError(400, "README.md metadata must be a YAML mapping")
    tags = (meta or {}).get("tags")
    if tags is not None and not (isinstance(tags, list) and all(isinstance(t, str) for t in tags)):
        raise HubError(400, "'tags' must be a list of strings")


def _make_handler(hub: LocalHub) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, format, *args):  # noqa: A002 - keep test output quiet
            pass

        # -------------------------------------------------------------- plumbing
        def _body(self) -> bytes:
            length = int(self.headers.get("Content-Length") or 0)
            return self.rfile.read(length) if length else b""

        def _send(self, status: int, payload=None, headers: dict | None = None, raw: bytes | None = None):
            body = raw if raw is not None else (b"" if payload is None else json.dumps(payload).encode())
            self.send_response(status)
            for key, value in (headers or {}).items():
                self.send_header(key, value)
            if raw is None:
                self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            if self.command != "HEAD":
                self.wfile.write(body)

        def _require_auth(self) -> None:
            if not (self.headers.get("Authorization") or "").startswith("Bearer "):
                raise HubError(401, "Invalid credentials in Authorization header")

        def _dispatch(self) -> None:
            split = urlsplit(self.path)
            query = {k: v[-1] for k, v in parse_qs(split.query).items()}
            # Split before unquoting: revisions arrive with '/' encoded as %2F.
            parts = [unquote(p) for p in split.path.strip("/").split("/")]
            hub.requests.append((self.command, split.path))
            body = self._body() if self.command in ("POST", "PUT", "DELETE") else b""
            try:
                self._route(parts, query, body)
            except HubError as err:
                headers = {"X-Error-Message": err.message}
                if err.error_code:
                    headers["X-Error-Code"] = err.error_code
                self._send(err.status, {"error": err.message, **err.extra}, headers)

        def _route(self, parts: list[str], query: dict, body: bytes) -> None:
            method = self.command
            if parts[:1] == ["api"]:
                return self._api(method, parts[1:], query, body)
            # /{datasets/}ns/name/resolve/{rev}/{path...}
            repo_type = REPO_TYPES.get(parts[0]) if parts else None
            rest = parts[1:] if repo_type and repo_type != "model" else parts
            repo_type = repo_type if repo_type and repo_type != "model" else "model"
            if len(rest) >= 5 and rest[2] == "resolve" and method in ("GET", "HEAD"):
                repo = hub.get_repo(repo_type, f"{rest[0]}/{rest[1]}")
                commit = repo.resolve(rest[3])
                path = "/".join(rest[4:])
                if path not in commit.files:
                    raise HubError(404, f"Entry not found: {path}", "EntryNotFound")
                content = hub._read_blob(commit.files[path])
                headers = {
                    "X-Repo-Commit": commit.oid,
                    "ETag": f'"{commit.files[path]}"',
                    "Content-Type": "application/octet-stream",
                    "Accept-Ranges": "bytes",
                }
                rng = self.headers.get("Range")
                if rng and rng.startswith("bytes=") and method == "GET":
                    start_s, _, end_s = rng[len("bytes=") :].partition("-")
                    start, end = int(start_s or 0), int(end_s) if end_s else len(content) - 1
                    headers["Content-Range"] = f"bytes {start}-{end}/{len(content)}"
                    return self._send(206, headers=headers, raw=content[start : end + 1])
                return self._send(200, headers=headers, raw=content)
            raise HubError(404, f"no route for {method} /{'/'.join(parts)}")

        def _api(self, method: str, parts: list[str], query: dict, body: bytes) -> None:
            if parts == ["whoami-v2"] and method == "GET":
                self._require_auth()
                return self._send(200, {"type": "user", "name": LOCAL_USER, "orgs": [], "auth": {}})
            if parts == ["repos", "create"] and method == "POST":
                self._require_auth()
                return self._send(200, hub.create_repo(json.loads(body)))
            if parts == ["validate-yaml"] and method == "POST":
                payload = json.loads(body)
                validate_card_yaml(payload.get("content", ""))
                return self._send(200, {"errors": [], "warnings": []})
            if len(parts) < 3 or parts[0] not in REPO_TYPES:
                raise HubError(404, f"no route for {method} /api/{'/'.join(parts)}")
            repo = hub.get_repo(REPO_TYPES[parts[0]], f"{parts[1]}/{parts[2]}")
            op, args = (parts[3], parts[4:]) if len(parts) > 3 else (None, [])
            if op is None and method == "GET":
                return self._send(200, hub.repo_info(repo, "main"))
            if op == "revision" and method == "GET":
                return self._send(200, hub.repo_info(repo, "/".join(args)))
            if op == "refs" and method == "GET":
                return self._send(200, hub.refs(repo))
            if op == "tree" and method == "GET":
                recursive = query.get("recursive", "false").lower() in ("1", "true")
                return self._send(200, hub.tree(repo, args[0], "/".join(args[1:]), recursive))
            if op == "paths-info" and method == "POST":
                paths = (
                    parse_qs(body.decode()).get("paths") if body[:1] != b"{" else json.loads(body)["paths"]
                )
                return self._send(200, hub.paths_info(repo, args[0], paths or []))
            if op == "preupload" and method == "POST":
                self._require_auth()
                return self._send(200, hub.preupload(repo, args[0], json.loads(body)))
            if op == "commit" and method == "POST":
                self._require_auth()
                create_pr = query.get("create_pr") == "1"
                return self._send(200, hub.commit(repo, args[0], body, create_pr))
            if op in ("tag", "branch") and method == "POST":
                self._require_auth()
                payload = json.loads(body) if body else {}
                if op == "tag":
                    hub.create_ref(repo, "tag", payload["tag"], args[0])
                else:
                    hub.create_ref(repo, "branch", args[0], payload.get("startingPoint") or "main")
                return self._send(200, {})
            if op in ("tag", "branch") and method == "DELETE":
                self._require_auth()
                hub.delete_ref(repo, op, args[0])
                return self._send(200, {})
            raise HubError(404, f"no route for {method} /api/{'/'.join(parts)}")

        do_GET = do_HEAD = do_POST = do_PUT = do_DELETE = _dispatch  # noqa: N815 (http.server names)

    return Handler
