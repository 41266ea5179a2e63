"""roadload.experiments: the experiments run on top of the algorithm packages, one module (or small subpackage)
each; ``scripts/`` holds their thin entry points (argument parsing lives here, in each module's ``main``).

- controllers: ``controller_comparison`` (+ ``time_matching``), ``headline`` (paired comparison and sensitivity
  map), ``optimum_benchmark`` (every controller against the full-route optimum, + ``fastsim_check``),
  ``headline_refit`` and ``headline_resolution`` (re-analyses of stored runs), ``truck_convergence``,
  ``truck_lambda_scan``;
- estimators: ``ch3_reproduction`` (chapter 3), ``fleet`` (chapter-5 fleet campaign), ``real_i3_ch5`` (chapter 5
  on the real BMW i3 trips), ``measurement_bias``, ``robustness/`` (sweeps to breakdown);
- RL: ``rl/`` (training, evaluation, highway, speed-shield effect, EcoTraffic-v0: ``traffic_training``,
  ``traffic_fidelity``);
- sim-to-real: ``sim2real/`` (the selftest, the real i3 trips, the JSON identity check) and its test worlds ``worlds/``;
- data: ``real_profiles`` (road profiles from the real logs);
- ``benchmarks/``: speed of every layer and the bitwise identity check, with old/new comparisons, and the
  parameter count of the compiled kernels (``kernel_signatures``);
- ``cli/``: the ``roadload`` command line, one module per command group.
"""
