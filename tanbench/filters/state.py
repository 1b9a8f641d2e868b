"""Particle state layout of the tightly coupled filter (Eq. 2) and the loose filter.

Tight: x = [E, N, U, pitch, roll, yaw, gyro bias x, gyro bias z] (m, rad, rad/s): the
cloud is an (8, M) array, a row per state and a column per particle; yaw is the Eq. 5
angle (counter-clockwise from north), unwrapped. Loose: x = [E, N] (m), (2, M).
"""

E, N, U, PITCH, ROLL, YAW, BX, BZ = range(8)
N_TIGHT = 8
N_LOOSE = 2
