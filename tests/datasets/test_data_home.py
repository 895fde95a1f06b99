"""Where the real data is looked for."""

from __future__ import annotations

import pytest

from o3d_rpointhop.datasets import _paths, data_home


@pytest.fixture
def isolated(tmp_path, monkeypatch):
    """No variable, a fresh home, and a checkout with no ``../shared/data``."""
    monkeypatch.delenv(_paths.ENV_VAR, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    (tmp_path / "home").mkdir()
    fake = tmp_path / "a" / "b" / "c" / "d" / "_paths.py"
    monkeypatch.setattr(_paths, "__file__", str(fake))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_lookup_order(isolated, monkeypatch):
    with pytest.raises(FileNotFoundError, match="no data folder found"):
        data_home()
    checkout = isolated / "a" / "shared" / "data"
    checkout.mkdir(parents=True)
    assert data_home() == checkout  # the developer fallback, last
    user = isolated / "home" / "o3d_rpointhop_data"
    user.mkdir()
    assert data_home() == user  # the user folder wins over the checkout
    named = isolated / "mine"
    named.mkdir()
    monkeypatch.setenv(_paths.ENV_VAR, str(named))
    assert data_home() == named  # the variable wins over both
    explicit = isolated / "explicit"
    explicit.mkdir()
    assert data_home(explicit) == explicit  # and data_dir over everything


def test_missing_named_folders_are_errors(isolated, monkeypatch):
    (isolated / "home" / "o3d_rpointhop_data").mkdir()
    monkeypatch.setenv(_paths.ENV_VAR, str(isolated / "nowhere"))
    with pytest.raises(FileNotFoundError, match="O3D_RPOINTHOP_DATA=.*is not a folder"):
        data_home()
    with pytest.raises(FileNotFoundError, match="does not exist"):
        data_home(isolated / "missing")
