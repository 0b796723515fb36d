"""Simulation stage: physics options, cabinet and hand entities, rooms, camera, the dm_control Task
and its gymnasium wrapper."""
