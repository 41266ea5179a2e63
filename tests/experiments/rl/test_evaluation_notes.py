"""The RL evaluation surfaces the MPC baseline's relaxed / infeasible plans and fallback brakes in its notes."""

from roadload.experiments.rl import evaluation


def test_mpc_baseline_relaxed_plans_are_noted(monkeypatch):
    def fake(name, env_config, seed, logs=None):
        out = {"arrived": True, "energy_kWh": 0.3, "trip_time": 200.0}
        if name == "mpc":
            out.update(relaxed_plans=2 if seed == 1001 else 0, infeasible_plans=0, fallback_brakes=1 if seed == 1001
                       else 0, worst_violation="stop at 100 m: 15.6 m/s against a limit of 1 m/s")
        return out

    monkeypatch.setattr(evaluation, "run_controller", fake)
    table, notes = evaluation.evaluation_table({}, {"road": "hilly"}, road_seeds=(1000, 1001),
                                               controllers=("cruise", "mpc"))
    assert len(table) == 4
    assert notes == ["mpc on road 1001: 2 relaxed and 0 infeasible plans (a stop or speed cap out of reach within "
                     "the comfort limits), 1 fallback brakes; worst: stop at 100 m: 15.6 m/s against a limit of 1 m/s"]
