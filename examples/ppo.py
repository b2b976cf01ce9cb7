"""Train Stable-Baselines3's PPO on a mix of courses for a few thousand steps and report steps/s.

.venv/bin/python examples/ppo.py [--steps 4096]
"""

import argparse
import time

from stable_baselines3 import PPO
from stable_baselines3.common.env_util import make_vec_env

import terrapref.sim.env  # noqa: F401  (registers terrapref/OffRoadNav-v1)

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--steps", type=int, default=4096, help="environment steps to train for")
args = parser.parse_args()

# Two envs; each draws its course per episode from the list, and "gen:*" is a new generated
# course every time. 64 x 80 one-hot class images suit SB3's default CNN.
env = make_vec_env(
    "terrapref/OffRoadNav-v1",
    n_envs=2,
    seed=0,
    env_kwargs={"scenario": ["demo_course", "gen:*"], "image_size": (64, 80), "image_encoding": "onehot"},
)
model = PPO("MultiInputPolicy", env, n_steps=512, batch_size=128, seed=0, device="cpu", verbose=0)
start = time.perf_counter()
model.learn(total_timesteps=args.steps)
elapsed = time.perf_counter() - start
print(f"{model.num_timesteps} steps in {elapsed:.1f} s: {model.num_timesteps / elapsed:.0f} steps/s")
