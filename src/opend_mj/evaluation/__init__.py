"""Evaluation stage: episodes (identity and jobs), the episode runner, the worker pool and the
resumable results file, grasp search, and scoring into the paper's tables."""
