"""Train PPO (stable-baselines3, optional: `pip install 'opend-mj[rl]'`) on the gymnasium environment.

    python examples/train_ppo.py --cabinets cabinets --steps 4096 [--num-envs 2] [--out ppo_opend.zip]

State observations with privileged ground truth (the handle's box), the dense reward, normalised
delta actions, drawers only: the easiest setting to start from. A few thousand steps only show
that the pipeline runs; opening drawers from scratch takes millions. Exits quietly (status 0) when
stable-baselines3 is not installed.
"""

from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")


def make_env(cabinets: str, hand: str):
    import gymnasium as gym

    import opend_mj.sim.gym_env  # noqa: F401  (registers the ids)

    return gym.make("opend/OpenDrawer-v0", cabinets=cabinets, split="train", hand=hand, obs_mode="state",
                    privileged=True, reward_mode="dense")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cabinets", default="cabinets")
    parser.add_argument("--hand", default="franka")
    parser.add_argument("--steps", type=int, default=4096)
    parser.add_argument("--num-envs", type=int, default=1, help=">1: a vector env of spawned processes")
    parser.add_argument("--out", default="ppo_opend.zip")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    try:
        from stable_baselines3 import PPO
        from stable_baselines3.common.env_util import make_vec_env
        from stable_baselines3.common.vec_env import SubprocVecEnv
    except ImportError:
        print("stable-baselines3 is not installed: pip install 'opend-mj[rl]'")
        return 0
    try:  # torch's optimisers import torch._dynamo, which loads triton's LLVM where it is installed; loaded
        import torch._dynamo  # noqa: F401  after MuJoCo's EGL (Mesa's LLVM) it crashes, so load it first
    except ImportError:
        pass

    kwargs = {"cabinets": args.cabinets, "hand": args.hand}
    if args.num_envs > 1:
        env = make_vec_env(make_env, n_envs=args.num_envs, seed=args.seed, env_kwargs=kwargs,
                           vec_env_cls=SubprocVecEnv, vec_env_kwargs={"start_method": "spawn"})
    else:
        env = make_vec_env(make_env, n_envs=1, seed=args.seed, env_kwargs=kwargs)
    model = PPO("MultiInputPolicy", env, n_steps=max(64, min(1024, args.steps // args.num_envs)), batch_size=64,
                learning_rate=3e-4, seed=args.seed, verbose=1)
    model.learn(total_timesteps=args.steps)
    model.save(args.out)
    env.close()

    # a short look at the trained policy: one episode per seed
    test = make_env(**kwargs)
    for seed in range(2):
        obs, info = test.reset(seed=1000 + seed)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, info = test.step(action)
            total += reward
            done = terminated or truncated
        print(f"seed {1000 + seed}: {info['cabinet']} '{info['instruction']}': return {total:.1f}, "
              f"success {info['success']}, open ratio {info['open_ratio']:.3f}")
    test.close()
    print(f"saved {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
