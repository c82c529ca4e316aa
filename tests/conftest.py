"""Shared pytest fixtures."""

from __future__ import annotations

import httpx
import pytest
from hub_server import LocalHub
from huggingface_hub import constants as hf_constants
from huggingface_hub.utils import _http as hf_http

DUMMY_HF_TOKEN = "hf_local_test_token"


class _LocalHubTransport(httpx.HTTPTransport):
    """Sends every Hub-bound request to the local hub and refuses any other host.

    ``RepoCard.validate()`` posts to a hard-coded ``https://huggingface.co/api/validate-yaml``; routing
    that host here keeps the validation running (against the local server) instead of disabling it.
    """

    HUB_HOSTS = ("huggingface.co", "hub-ci.huggingface.co")

    def __init__(self, hub_url: str):
        super().__init__()
        self._target = httpx.URL(hub_url)

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        if request.url.host in self.HUB_HOSTS:
            request.url = request.url.copy_with(
                scheme=self._target.scheme, host=self._target.host, port=self._target.port
            )
        elif (request.url.host, request.url.port) != (self._target.host, self._target.port):
            raise httpx.ConnectError(
                f"tests may not reach {request.url} (only the local hub)", request=request
            )
        return super().handle_request(request)


@pytest.fixture
def local_hub(tmp_path, monkeypatch) -> LocalHub:
    """A local Hub server that ``huggingface_hub`` (and so LeRobot's push/download code) talks to.

    Sets ``HF_ENDPOINT``/``HF_TOKEN`` (env and ``huggingface_hub.constants``) and routes the hard-coded
    huggingface.co host to the local server. Inspect uploads with ``local_hub.files(repo_id, repo_type)``
    or the materialised branch at ``local_hub.checkout_dir(repo_id, repo_type)``.
    """
    hub = LocalHub(tmp_path / "local_hub").start()
    monkeypatch.setenv("HF_ENDPOINT", hub.url)
    monkeypatch.setenv("HF_TOKEN", DUMMY_HF_TOKEN)
    monkeypatch.delenv("HF_HUB_OFFLINE", raising=False)
    monkeypatch.setattr(hf_constants, "ENDPOINT", hub.url)
    monkeypatch.setattr(
        hf_constants, "HUGGINGFACE_CO_URL_TEMPLATE", hub.url + "/{repo_id}/resolve/{revision}/{filename}"
    )
    monkeypatch.setattr(hf_constants, "HF_HUB_OFFLINE", False)
    # huggingface_hub trusts (parses URLs of, forwards auth to) the hosts of the configured endpoint.
    monkeypatch.setattr(hf_constants, "HF_URL_HOSTS", hf_constants.HF_URL_HOSTS | {"127.0.0.1"})
    # Downloads without a local_dir land in a per-test cache, never in the user's ~/.cache.
    monkeypatch.setattr(hf_constants, "HF_HUB_CACHE", str(tmp_path / "hf_hub_cache"))

    def client_factory() -> httpx.Client:
        return httpx.Client(
            transport=_LocalHubTransport(hub.url),
            event_hooks={"request": [hf_http.hf_request_event_hook]},
            follow_redirects=True,
            timeout=60,
        )

    hf_http.set_client_factory(client_factory)
    try:
        yield hub
    finally:
        hf_http.set_client_factory(hf_http.default_client_factory)
        hub.stop()
