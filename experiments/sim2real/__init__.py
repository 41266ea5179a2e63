"""Experiments on the sim-to-real diagnosis: the selftest on withheld and injected effects over its test worlds
(roadload's simulator, the independent model, FASTSim, the real BMW i3 trips), and the check that a refactoring
leaves the diagnosis JSON unchanged (:mod:`.identity`)."""
