"""Virtual Orthoglide: geometry, kinematics, PyBullet machine, gauges and Gymnasium env."""
