"""Policy stage: handle solvers (oracle and learned), perception from depth, and the planner."""
