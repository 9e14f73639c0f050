"""The paper's model as a Gymnasium environment: ``corraoi/CorrelatedAoI-v0``.

``import corraoi.gym`` registers it; Gymnasium's module prefix makes it in one call without
that import (``import corraoi`` never imports gymnasium: it is the optional extra ``gym``)::

    import gymnasium
    env = gymnasium.make("corraoi.gym:corraoi/CorrelatedAoI-v0", instance="I1",
                         horizon=10_000, record="runs/agent-{episode}.mcap")
    obs, info = env.reset(seed=0)        # the hidden path of `corraoi record --seed 0`
    obs, reward, terminated, truncated, info = env.step(1)   # arm 2

* **action**: the arm, ``Discrete(K)``: 0..K-1 by Gymnasium's convention, arms 1..K in
  the log and everywhere else in corraoi;
* **observation**: what a scheduler legitimately sees after a slot: ``[success, age]``
  (int64; before the first slot ``[0, 1]``), and with ``pseudo_rewards=True`` a dict of
  that (``"slot"``) and the pseudo-rewards ``s[arm, k, success]`` of every arm ``k``
  (``"pseudo_rewards"``) that the correlated model gives;
* **reward**: minus the age after the slot (``reward="aoi"``), or minus the slot's regret
  increment, age - oracle's age (``reward="regret"``): an episode's return is minus its
  sum of ages, or minus its pathwise regret;
* an episode is ``horizon`` slots: the last step says ``truncated``; ``terminated`` is
  never set (the model has no end state);
* **info**: ``t``, and what the agent must not use: the hidden state ``x`` (1..n), the
  oracle's age and the pathwise regret so far;
* ``reset(seed=s)``: the hidden path of seed ``s`` (the engine's draws, block by block, so
  ``reset`` costs the same for any horizon): the run is paired with every built-in
  policy's run of ``corraoi record --seed s`` on the same instance and channel. Without a
  seed, the episode's seed is drawn from the environment's generator (``info["seed"]``);
* ``record=PATH``: every step goes to a slot log through :class:`corraoi.Logger` (the
  hidden state included); each ``reset`` starts a new log at that path, replacing the last
  episode's, unless ``{episode}`` in it numbers them. A file there before this environment
  wrote it is refused, as ``corraoi record`` refuses it, unless ``force=True``.
"""

from __future__ import annotations

import os
from typing import Any

from corraoi.extras import require

require("gym", "corraoi.gym (the Gymnasium environment)")

import gymnasium  # noqa: E402
import numpy as np  # noqa: E402
from gymnasium import spaces  # noqa: E402

from corraoi.engine.paths import HiddenPaths  # noqa: E402
from corraoi.errors import SlotError, UsageError  # noqa: E402
from corraoi.model.theory import analyse, policy_pseudo_rewards  # noqa: E402

#: The id ``import corraoi.gym`` registers.
ENV_ID = "corraoi/CorrelatedAoI-v0"
#: What the reward is minus: the age, or the slot's regret increment.
REWARDS = ("aoi", "regret")
#: Slots of the hidden path drawn at a time.
PATH_BLOCK = 4096


class CorrelatedAoIEnv(gymnasium.Env[Any, np.int64]):
    """One correlated AoI bandit run per episode (module docstring). ``instance``: what
    :func:`corraoi.record` takes; ``channel``: ``iid``, ``markov`` or ``trace:PATH``;
    ``policy``, ``source`` and ``version``: what the log (``record``) names as its writer;
    ``force``: ``record`` may replace files that were there before."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        instance: Any = "I1",
        horizon: int = 10_000,
        *,
        channel: str | None = None,
        reward: str = "aoi",
        pseudo_rewards: bool = False,
        record: str | os.PathLike[str] | None = None,
        force: bool = False,
        policy: str = "agent",
        source: str = "corraoi.gym " + ENV_ID,
        version: str = "",
    ) -> None:
        from corraoi.face import resolve
        from corraoi.limits import check_horizon

        self.instance = resolve.instance(instance)
        check_horizon(horizon)
        self.horizon = int(horizon)
        self.channel = resolve.channel(channel, self.instance)
        self.channel.check(self.instance, self.horizon)
        self._channel_word = channel
        if reward not in REWARDS:
            raise UsageError(f"reward {reward!r}: expected one of {', '.join(REWARDS)}")
        self.reward_kind = reward
        self.pseudo_rewards = bool(pseudo_rewards)
        self.record = None if record is None else os.fspath(record)
        self.force = bool(force)
        self.policy, self.source, self.version = policy, source, version
        K = self.instance.K
        self.action_space = spaces.Discrete(K)
        slot = spaces.Box(low=np.array([0, 1]), high=np.array([1, self.horizon + 1]),
                          dtype=np.int64)  # fmt: skip
        self.observation_space: spaces.Space[Any] = slot
        if self.pseudo_rewards:
            self.observation_space = spaces.Dict(
                {"slot": slot, "pseudo_rewards": spaces.Box(0.0, 1.0, (K,), np.float64)}
            )
        theory = analyse(self.instance)
        self._best = theory.best_arm
        self._Y = np.asarray(self.instance.Y, dtype=bool).tolist()
        self._pseudo = policy_pseudo_rewards(self.instance)  # s[l, k, r]
        self._paths: HiddenPaths | None = None
        self._xs: list[int] = []
        self._t = 0
        self._first = 0  # the slot before self._xs[0]
        self._logger: Any = None
        self._written: set[str] = set()  # paths this environment wrote: replaced freely
        self.episode = -1
        self.seed_of_episode: int | None = None

    # ------------------------------------------------------------------ the API

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        from corraoi.limits import MAX_SEED, check_seed

        super().reset(seed=seed)
        self._close_log()
        if seed is None:
            seed = int(self.np_random.integers(0, MAX_SEED, endpoint=True))
        check_seed(seed, name="seed")
        self.seed_of_episode = int(seed)
        self.episode += 1
        self._paths = HiddenPaths(self.instance, [int(seed)], channel=self.channel)
        self._xs, self._first, self._t = [], 0, 0
        self._aoi, self._oracle_aoi, self._regret = 1, 1, 0
        if self.record is not None:
            self._open_log()
        obs = self._observe(0, 1, None)
        return obs, {"t": 0, "seed": self.seed_of_episode}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        t = self._t + 1
        if self._paths is None:
            raise UsageError("step() before reset(): call env.reset(seed=...) first")
        if t > self.horizon:
            raise UsageError(f"step() at slot {t}: the episode ended at its horizon "
                             f"{self.horizon}; call env.reset() for the next")  # fmt: skip
        try:
            a = int(action)
        except (TypeError, ValueError):
            raise SlotError(f"slot {t}: action {action!r}: expected an arm 0..{len(self._Y) - 1}"
                            ) from None  # fmt: skip
        if not 0 <= a < len(self._Y) or isinstance(action, (bool, np.bool_)):
            raise SlotError(f"slot {t}: action {action!r}: expected an arm "
                            f"0..{len(self._Y) - 1} (Gymnasium numbers arms from 0)")  # fmt: skip
        j = t - 1 - self._first
        if j >= len(self._xs):
            self._first = t - 1
            self._xs = self._paths.draw(min(PATH_BLOCK, self.horizon - t + 1))[0].tolist()
            j = 0
        x = self._xs[j]
        ok = self._Y[a][x]
        aoi = 1 if ok else self._aoi + 1
        oracle = 1 if self._Y[self._best][x] else self._oracle_aoi + 1
        self._aoi, self._oracle_aoi = aoi, oracle
        self._regret += aoi - oracle
        self._t = t
        if self._logger is not None:
            self._logger.slot(a + 1, ok, x=x + 1)
        reward = float(-aoi if self.reward_kind == "aoi" else oracle - aoi)
        end = t == self.horizon
        if end and self._logger is not None:
            self._close_log()
        info = {"t": t, "x": x + 1, "oracle_aoi": oracle, "regret": self._regret}
        return self._observe(int(ok), aoi, a), reward, False, end, info

    def close(self) -> None:
        self._close_log()
        super().close()

    # ------------------------------------------------------------------ internals

    def _observe(self, success: int, aoi: int, arm: int | None) -> Any:
        slot = np.array([success, aoi], dtype=np.int64)
        if not self.pseudo_rewards:
            return slot
        pseudo = (np.ones(len(self._Y)) if arm is None
                  else self._pseudo[arm, :, success].astype(np.float64))  # fmt: skip
        return {"slot": slot, "pseudo_rewards": pseudo}

    def _open_log(self) -> None:
        from corraoi.face.logger import Logger

        assert self.record is not None and self.seed_of_episode is not None
        path = self.record.replace("{episode}", str(self.episode))
        again = self.force or os.path.abspath(path) in self._written
        self._logger = Logger(path, instance=self.instance, horizon=self.horizon,
                              policy=self.policy, seed=self.seed_of_episode,
                              channel=self._channel_word, source=self.source,
                              version=self.version, overwrite=again)  # fmt: skip
        self._written.add(os.path.abspath(path))

    def _close_log(self) -> None:
        if self._logger is not None:
            logger, self._logger = self._logger, None
            logger.close()


class CorrelatedAoIVectorEnv(gymnasium.vector.VectorEnv[np.ndarray, np.ndarray, np.ndarray]):
    """``num_envs`` runs of the model stepped at once, without a Python loop per run:
    ``gymnasium.make_vec(ENV_ID, num_envs=256, vectorization_mode="vector_entry_point",
    instance="I1", horizon=10_000)``. Each sub-environment is :class:`CorrelatedAoIEnv`'s
    (the same observation, reward and info, as arrays over the runs), on its own hidden path:
    ``reset(seed=s)`` gives sub-environment ``i`` the path of seed ``s + i`` (a sequence of
    seeds gives each its own). The runs share the horizon, so every episode ends at once;
    the next ``step`` starts new ones (Gymnasium's next-step autoreset) on seeds drawn from
    the environment's generator. Neither ``record`` nor ``pseudo_rewards`` is offered here:
    log a run through the plain environment."""

    metadata: dict[str, Any] = {
        "render_modes": [],
        "autoreset_mode": gymnasium.vector.AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        instance: Any = "I1",
        horizon: int = 10_000,
        *,
        channel: str | None = None,
        reward: str = "aoi",
    ) -> None:
        from gymnasium.vector.utils import batch_space

        single = CorrelatedAoIEnv(instance, horizon, channel=channel, reward=reward)
        if not isinstance(num_envs, int) or num_envs < 1:
            raise UsageError(f"num_envs {num_envs!r}: expected an integer >= 1")
        self.num_envs = num_envs
        self.instance, self.channel, self.horizon = single.instance, single.channel, single.horizon
        self.reward_kind = single.reward_kind
        self.single_action_space = single.action_space
        self.single_observation_space = single.observation_space
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._Y = np.asarray(self.instance.Y, dtype=bool)
        self._best = analyse(self.instance).best_arm
        self._paths: HiddenPaths | None = None
        self._ended = False
        self.seeds: np.ndarray | None = None

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        from corraoi.limits import MAX_SEED, check_seed

        N = self.num_envs
        if seed is None or isinstance(seed, int):
            super().reset(seed=seed)
            first = (int(self.np_random.integers(0, MAX_SEED - N + 1, endpoint=True))
                     if seed is None else seed)  # fmt: skip
            check_seed(first, runs=N, name="seed")
            seeds = np.arange(first, first + N, dtype=np.int64)
        else:
            seeds = np.asarray(seed, dtype=np.int64)
            if seeds.shape != (N,):
                raise UsageError(f"seed: {seeds.size} seeds for {N} sub-environments")
            super().reset(seed=int(seeds[0]))
        self.seeds = seeds
        self._paths = HiddenPaths(self.instance, seeds, channel=self.channel)
        self._xs = np.zeros((N, 0), dtype=np.int64)
        self._first, self._t, self._ended = 0, 0, False
        self._aoi = np.ones(N, dtype=np.int64)
        self._oracle_aoi = np.ones(N, dtype=np.int64)
        self._regret = np.zeros(N, dtype=np.int64)
        obs = np.tile(np.array([0, 1], dtype=np.int64), (N, 1))
        return obs, {"t": 0, "seed": seeds.copy()}

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        N = self.num_envs
        if self._paths is None:
            raise UsageError("step() before reset(): call envs.reset(seed=...) first")
        if self._ended:  # next-step autoreset: this step only starts the new episodes
            obs, info = self.reset()
            zeros = np.zeros(N, dtype=bool)
            return obs, np.zeros(N), zeros, zeros.copy(), info
        t = self._t + 1
        arms = actions if actions.__class__ is np.ndarray else np.asarray(actions)
        if arms.shape != (N,) or arms.dtype.kind not in "iu":
            raise SlotError(f"slot {t}: actions of shape {arms.shape} ({arms.dtype}): expected "
                            f"{N} integer arms, one per sub-environment")  # fmt: skip
        if arms.min() < 0 or arms.max() >= self.instance.K:
            i = int(np.argmax((arms < 0) | (arms >= self.instance.K)))
            raise SlotError(f"slot {t}: sub-environment {i}: action {int(arms[i])}: expected an "
                            f"arm 0..{self.instance.K - 1}")  # fmt: skip
        j = t - 1 - self._first
        if j >= self._xs.shape[1]:
            self._first = t - 1
            self._xs = self._paths.draw(min(PATH_BLOCK, self.horizon - t + 1))
            j = 0
        x = self._xs[:, j]
        ok = self._Y[arms, x]
        aoi = self._aoi + 1
        aoi[ok] = 1
        oracle = self._oracle_aoi + 1
        oracle[self._Y[self._best, x]] = 1
        self._aoi, self._oracle_aoi = aoi, oracle
        self._regret += aoi - oracle
        self._t = t
        reward = np.negative(aoi if self.reward_kind == "aoi" else aoi - oracle,
                             dtype=np.float64)  # fmt: skip
        self._ended = t == self.horizon
        obs = np.empty((N, 2), dtype=np.int64)
        obs[:, 0] = ok
        obs[:, 1] = aoi
        info = {"t": t, "x": x + 1, "oracle_aoi": oracle, "regret": self._regret.copy()}
        ended = np.ones(N, dtype=bool) if self._ended else np.zeros(N, dtype=bool)
        return obs, reward, np.zeros(N, dtype=bool), ended, info


gymnasium.register(id=ENV_ID, entry_point="corraoi.gym:CorrelatedAoIEnv",
                   vector_entry_point="corraoi.gym:CorrelatedAoIVectorEnv")  # fmt: skip

__all__ = ["ENV_ID", "REWARDS", "CorrelatedAoIEnv", "CorrelatedAoIVectorEnv"]
