"""The native vector env of roadload/EcoDrive-v0: every sub-env equals the single env (same seeds) exactly -- both run
the one compiled step -- through autoresets (next-step and same-step), truncation and termination; SB3 adapter; input
errors."""

import gymnasium as gym
import numpy as np
import pytest

import roadload  # noqa: F401  (registers the ids)
from roadload.gym.config import GymConfigError
from roadload.gym.ecodrive import EcoDriveEnv
from roadload.gym.vector import COST_NAMES, INFO_SCALARS, EcoDriveVectorEnv, openmp_wait_policy

TOL = 0.0  # the single env is the compiled step with one sub-env: no difference at all


def _singles(config, n, seed):
    envs = [EcoDriveEnv(config=dict(config)) for _ in range(n)]
    return envs, [e.reset(seed=seed + i) for i, e in enumerate(envs)]


def _close(a, b, what):
    assert np.allclose(a, b, rtol=0, atol=TOL), f"{what}: {a} != {b}"


def _check_info(vinfo, i, sinfo, with_terms):
    for k in INFO_SCALARS:
        assert vinfo["_" + k][i]
        _close(vinfo[k][i], sinfo[k], k)
    for k in COST_NAMES:
        _close(vinfo["return_costs"][k][i], sinfo["return_costs"][k], f"return_costs.{k}")
    if with_terms:
        for k in COST_NAMES:
            _close(vinfo["terms"][k][i], sinfo["terms"][k], f"terms.{k}")
            _close(vinfo["costs"][k][i], sinfo["costs"][k], f"costs.{k}")
    else:
        assert "terms" not in vinfo or not vinfo["_terms"][i]


def test_make_vec_builds_the_native_env():
    venv = gym.make_vec("roadload/EcoDrive-v0", num_envs=4, vectorization_mode="vector_entry_point",
                        config={"route_length": 300.0})
    assert isinstance(venv.unwrapped, EcoDriveVectorEnv) and isinstance(venv, gym.vector.VectorEnv)
    single = EcoDriveEnv(config={"route_length": 300.0})
    assert venv.single_observation_space == single.observation_space
    assert venv.observation_space.shape == (4, single.observation_space.shape[0])
    assert venv.action_space.shape == (4, 1)
    obs, info = venv.reset(seed=1)
    assert obs.shape == (4, single.observation_space.shape[0]) and obs.dtype == np.float32
    assert venv.observation_space.contains(obs)


@pytest.mark.parametrize("config", [
    {"route_length": 150.0},                       # episodes terminate at the route end
    {"route_length": 2000.0, "time_limit": 6.0},   # episodes truncate at the time limit
    {"route_length": 400.0, "road": "city", "effects": {"wind": {"mean_speed": 6.0}}},  # stops, wind
    {"route_length": 150.0, "road": "city", "speed_shield": True, "shield_margin": 5.0,
     "time_limit": 12.0},  # the speed shield caps the commands
])
def test_each_sub_env_equals_the_single_env_next_step_autoreset(config):
    n, seed, steps = 3, 11, 320
    venv = EcoDriveVectorEnv(n, config=dict(config))
    vobs, vinfo = venv.reset(seed=seed)
    singles, first = _singles(config, n, seed)
    for i, (o, inf) in enumerate(first):
        _close(vobs[i], o, "reset obs")
        _check_info(vinfo, i, inf, with_terms=False)
    rng = np.random.default_rng(0)
    pending = [False] * n
    episodes = [0] * n
    for _ in range(steps):
        a = rng.uniform(-0.6, 1.0, (n, 1)).astype(np.float32)
        vobs, vr, vte, vtr, vinfo = venv.step(a)
        for i, env in enumerate(singles):
            if pending[i]:  # next-step autoreset: the action is ignored, the new episode's first observation
                o, inf = env.reset()
                r, te, tr, with_terms = 0.0, False, False, False
                pending[i] = False
            else:
                o, r, te, tr, inf = env.step(a[i])
                with_terms = True
                pending[i] = te or tr
                episodes[i] += pending[i]
            _close(vobs[i], o, "obs")
            _close(vr[i], r, "reward")
            assert (bool(vte[i]), bool(vtr[i])) == (te, tr)
            _check_info(vinfo, i, inf, with_terms)
    assert min(episodes) >= 1, f"no autoreset exercised: {episodes}"


def _same_step_rollout(config, n, seed, steps, action_low, rng_seed, check_final) -> int:
    """Random actions in [action_low, 1] through the same-step vector env and n single envs side by side: rewards and
    observations equal, ``check_final(vinfo, i, o, inf)`` at every termination / truncation of sub-env i (before the
    single env resets; it returns the reset info check), returns the number of finished episodes."""
    venv = EcoDriveVectorEnv(n, config=dict(config), autoreset_mode="same_step")
    venv.reset(seed=seed)
    singles, _ = _singles(config, n, seed)
    rng = np.random.default_rng(rng_seed)
    finals = 0
    for _ in range(steps):
        a = rng.uniform(action_low, 1.0, (n, 1)).astype(np.float32)
        vobs, vr, vte, vtr, vinfo = venv.step(a)
        for i, env in enumerate(singles):
            o, r, te, tr, inf = env.step(a[i])
            _close(vr[i], r, "reward")
            if te or tr:
                finals += 1
                after_reset = check_final(vinfo, i, o, inf)
                o, inf = env.reset()
                after_reset(inf)
            _close(vobs[i], o, "obs")
    return finals


def test_same_step_autoreset_reports_the_final_observation():
    def check(vinfo, i, o, inf):
        assert vinfo["_final_obs"][i]
        _close(vinfo["final_obs"][i], o, "final obs")
        _close(vinfo["final_info"]["s"][i], inf["s"], "final info s")
        return lambda reset_info: None

    assert _same_step_rollout({"route_length": 120.0}, 2, 5, 300, 0.0, 1, check) >= 2


def test_bad_input_is_named():
    venv = EcoDriveVectorEnv(2, config={"route_length": 300.0})
    venv.reset(seed=0)
    with pytest.raises(ValueError, match="non-finite"):
        venv.step(np.array([[0.1], [np.nan]], dtype=np.float32))
    with pytest.raises(ValueError, match=r"shape \(2, 1\)"):
        venv.step(np.zeros((3, 1), dtype=np.float32))
    with pytest.raises(ValueError, match="outside the bounds"):
        venv.step(np.array([[0.1], [1.5]], dtype=np.float32))
    with pytest.raises(GymConfigError, match="observation"):
        EcoDriveVectorEnv(2, config={"observation": "can"})
    with pytest.raises(GymConfigError, match="num_envs"):
        EcoDriveVectorEnv(0)
    with pytest.raises(GymConfigError, match="autoreset_mode"):
        EcoDriveVectorEnv(1, autoreset_mode="sometimes")



def test_reset_options_the_batch_shares_are_refused_not_ignored():
    """The compiled step reads the reward weights once for the batch: a per-sub-env reward change used to be
    accepted and silently ignored. Per-sub-env options it does honour still work (a new road for one sub-env)."""
    venv = EcoDriveVectorEnv(2, config={"route_length": 300.0})
    venv.reset(seed=0)
    with pytest.raises(GymConfigError, match=r"\['reward'\].*make_vec"):
        venv.reset(options={"reward": {"energy": 2.0}, "reset_mask": np.array([True, False])})
    with pytest.raises(GymConfigError, match="stop_speed"):
        venv.reset(options={"stop_speed": 2.0})
    obs, _ = venv.reset(seed=0, options={"road_seed": 7, "reset_mask": np.array([False, True])})
    single = EcoDriveEnv(config={"route_length": 300.0, "road_seed": 7})
    single_obs, _ = single.reset(seed=1)
    np.testing.assert_allclose(obs[1], single_obs, atol=1e-9)

def test_sb3_adapter_episode_bookkeeping():
    pytest.importorskip("stable_baselines3")
    from roadload.gym.sb3 import SB3VecEnv

    n = 2
    venv = SB3VecEnv(EcoDriveVectorEnv(n, config={"route_length": 120.0}, autoreset_mode="same_step"))
    venv.seed(3)
    obs = venv.reset()
    assert obs.shape == (n, venv.observation_space.shape[0])
    single = EcoDriveEnv(config={"route_length": 120.0})
    single.reset(seed=3)
    ret, length = 0.0, 0
    for _ in range(400):
        venv.step_async(np.full((n, 1), 0.8, dtype=np.float32))
        obs, rew, done, infos = venv.step_wait()
        _, r, te, tr, _ = single.step(np.array([0.8], dtype=np.float32))
        ret += r
        length += 1
        if done[0]:
            assert te or tr
            ep = infos[0]["episode"]
            assert ep["l"] == length and abs(ep["r"] - ret) < 1e-4  # float32 rewards in SB3
            assert infos[0]["terminal_observation"].shape == obs[0].shape
            assert infos[0]["TimeLimit.truncated"] == (tr and not te)
            break
    else:
        pytest.fail("no episode finished in 400 steps of 0.8 traction on a 120 m route")
    with pytest.raises(ValueError, match="same_step"):
        SB3VecEnv(EcoDriveVectorEnv(1))


@pytest.mark.slow  # the first compile of the parallel step kernel: ~30 s of CPU that no other CI test needs
def test_two_threads_give_the_one_thread_trajectories():
    """threads=2 (reached through gymnasium.make_vec's keyword) splits the vehicles over numba threads; every
    sub-env's observation, reward, flags and info equal the 1-thread env's to 1e-9 through autoresets, for an odd N
    (uneven blocks) with the speed shield on, and the bare physics too."""
    config = {"route_length": 150.0, "road": "city", "speed_shield": True, "shield_margin": 5.0, "time_limit": 12.0}
    n, seed = 7, 3
    envs = [gym.make_vec("roadload/EcoDrive-v0", num_envs=n, vectorization_mode="vector_entry_point",
                         threads=t, config=dict(config)).unwrapped for t in (1, 2)]
    assert [e.threads for e in envs] == [1, 2]
    # numba's OpenMP threads sleep rather than spin when idle unless the user chose otherwise (vector.py: Threads)
    assert openmp_wait_policy() != "default"
    first = [e.reset(seed=seed) for e in envs]
    _close(first[0][0], first[1][0], "reset obs")
    rng = np.random.default_rng(1)
    done = 0
    for _ in range(200):
        a = rng.uniform(-0.6, 1.0, (n, 1)).astype(np.float32)
        (o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2) = (e.step(a) for e in envs)
        _close(o1, o2, "obs")
        _close(r1, r2, "reward")
        assert np.array_equal(te1, te2) and np.array_equal(tr1, tr2)
        for k in INFO_SCALARS:
            _close(i1[k], i2[k], k)
        done += int((te1 | tr1).sum())
    assert done >= n, f"too few autoresets exercised: {done}"
    u = rng.uniform(-1, 1, n)
    for _ in range(20):
        for e in envs:
            e.bare_physics_step(u)
    states = [e.batch.fleet_records().vehicles["state"] for e in envs]
    assert states[0].tobytes() == states[1].tobytes(), "bare physics state"



def test_action_forms_and_kept_infos():
    """Every accepted action form (float32 / float64 (n, 1), a float64 (n,) vector, values within the bound
    tolerance outside [-1, 1]) gives the float32 path's trajectory; a returned info / reward is never overwritten by
    a later step (fresh arrays per step); obs_scaling 'si' equals the single env too."""
    config = {"route_length": 150.0, "obs_scaling": "si"}
    n, seed = 3, 4
    envs = [EcoDriveVectorEnv(n, config=dict(config)) for _ in range(4)]
    for e in envs:
        e.reset(seed=seed)
    singles, _ = _singles(config, n, seed)
    rng = np.random.default_rng(2)
    kept = []
    for k in range(160):
        a32 = rng.uniform(-0.5, 1.0, (n, 1)).astype(np.float32)
        if k % 7 == 0:
            a32[0, 0] = np.float32(1.0 + 5e-7)  # inside the tolerance: clipped to 1
        forms = [a32, a32.astype(np.float64), a32[:, 0].astype(np.float64), list(a32[:, 0])]
        outs = [e.step(f) for e, f in zip(envs, forms)]
        for o, r, te, tr, inf in outs[1:]:
            assert np.array_equal(o, outs[0][0]) and np.array_equal(r, outs[0][1])
            assert np.array_equal(te, outs[0][2]) and np.array_equal(inf["s"], outs[0][4]["s"])
        o, r, te, tr, inf = outs[0]
        for i, env in enumerate(singles):
            so, sr, ste, strunc, sinf = env.step(np.clip(a32[i], -1.0, 1.0))
            _close(o[i], so, "si obs")
            _close(r[i], sr, "reward")
            if ste or strunc:
                env.reset()
        kept.append((k, r.copy(), r, inf["s"].copy(), inf["s"], inf.get("terms", {}).get("energy")))
        if any(te) or any(outs[0][3]):
            break
    for k, r_copy, r, s_copy, s, _ in kept:
        assert np.array_equal(r, r_copy) and np.array_equal(s, s_copy), f"step {k}'s arrays were overwritten"
    assert len(kept) > 20


def test_same_step_final_info_has_the_single_env_terms_and_the_new_episode_info():
    """Same-step autoreset through terminations with the speed shield on (city road, stops): final_info carries the
    last step's terms / costs / return costs of the single env, and the info of a reset sub-env is the single env's
    reset info (no terms)."""
    config = {"route_length": 120.0, "road": "city", "speed_shield": True, "shield_margin": 4.0}

    def check(vinfo, i, o, inf):
        assert vinfo["_final_info"][i]
        _check_info(vinfo["final_info"], i, inf, with_terms=True)
        return lambda reset_info: _check_info(vinfo, i, reset_info, with_terms=False)

    assert _same_step_rollout(config, 3, 8, 400, 0.2, 3, check) >= 3


def test_openmp_runtime_loaded_by_torch_is_detected():
    """torch loads libgomp, which reads OMP_WAIT_POLICY only then: the vector env must see that (and warn) rather
    than believe its late PASSIVE default is in effect."""
    pytest.importorskip("torch")
    from roadload.gym.vector import _openmp_runtime_loaded

    assert _openmp_runtime_loaded()


def test_route_end_and_time_limit_in_the_same_step_is_terminated_not_truncated():
    """A step that reaches the route end exactly at the time limit ends the episode as terminated (the MDP's end),
    not truncated, in the single env and in every sub-env of the vector env."""
    action = np.array([0.8], dtype=np.float32)
    probe = EcoDriveEnv(config={"route_length": 150.0})
    probe.reset(seed=7)
    steps, terminated = 0, False
    while not terminated:
        _, _, terminated, truncated, info = probe.step(action)
        steps += 1
        assert not truncated
    config = {"route_length": 150.0, "time_limit": info["t"]}  # the limit falls on the terminating step
    single = EcoDriveEnv(config=config)
    single.reset(seed=7)
    venv = EcoDriveVectorEnv(2, config=config)
    venv.reset(seed=[7, 7])
    for k in range(steps):
        _, _, te, tr, inf = single.step(action)
        _, _, vte, vtr, vinfo = venv.step(np.tile(action, (2, 1)))
        last = k == steps - 1
        assert (te, tr) == (last, False), (k, te, tr)
        assert vte.tolist() == [last, last] and vtr.tolist() == [False, False], (k, vte, vtr)
    assert inf["t"] >= config["time_limit"] - 1e-9 and vinfo["t"][0] >= config["time_limit"] - 1e-9
