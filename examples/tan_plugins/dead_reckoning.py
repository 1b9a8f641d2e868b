"""Dead reckoning: the navigation system's own solution, with no terrain aiding.

The floor every TAN method should beat. It reports the navigation solution at each
update and, as its uncertainty, the initial position uncertainty (a uniform square of
side ``filter.initial_area_m``) grown by the velocity process noise.
"""


def run(ctx):
    """Dead reckoning: the navigation system's solution, no terrain aiding."""
    upd = ctx.updates.imu
    pos = ctx.nav.pos[upd]
    f = ctx.scenario.filter
    elapsed = ctx.updates.t - ctx.updates.t[0]
    var = f.initial_area_m ** 2 / 12.0 + (f.process_noise_velocity_mps ** 2) * elapsed * ctx.scenario.sampling_time_s
    return {"east": pos[:, 0], "north": pos[:, 1], "up": pos[:, 2], "var_e": var, "var_n": var}
