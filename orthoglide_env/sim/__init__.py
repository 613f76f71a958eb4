"""The simulator: the URDF writer and the PyBullet closed-chain machine."""
