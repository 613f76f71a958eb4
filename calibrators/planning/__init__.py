"""Experiment planning on the linearised model: :mod:`~calibrators.planning.belief` (what an
experiment knows), :mod:`~calibrators.planning.pricing` (what each move costs and gains),
:mod:`~calibrators.planning.search` (the greedy choice), :mod:`~calibrators.planning.
slot_table` (what a gauge does where), :mod:`~calibrators.planning.world_terms` (the
lab's world) and :mod:`~calibrators.planning.bound` (the least error any plan can reach)."""
