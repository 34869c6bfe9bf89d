"""The RL guide (docs/guides/rl.md): its snippets run as written when pasted into the REPL from the
repository root (the RL env batched with jax.vmap, and the Gymnasium vector env)."""

from pathlib import Path

from tests.repl import run_page

REPO = Path(__file__).resolve().parents[2]


def test_rl_guide_snippets(monkeypatch):
  monkeypatch.chdir(REPO)
  scopes = run_page(REPO / "docs" / "guides" / "rl.md")
  assert len(scopes) == 2
  env_scope, gym_scope = scopes
  assert env_scope["state"].obs.shape == (64, 98)
  assert float(env_scope["state"].metrics["keepout_entries"].sum()) == 0.0
  assert gym_scope["obs"].shape == (8, 98)
