"""True vehicle motion: the paper's dive-and-lawn-mower runs and generic survey patterns.

A trajectory is planned as piecewise-constant pitch and yaw rates (roll stays zero)
at constant speed along the body forward axis, then sampled at the IMU rate. Angles
are exact (piecewise linear); positions integrate the analytic velocity with
Simpson's rule on each sample interval, so the truth is exact to far below a
millimetre. The IMU's error-free outputs (angular rate, specific force) are derived
from the same analytic motion, so integrating them reproduces the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tanbench.earth import EARTH_RATE, gravity, radii_of_curvature
from tanbench.vehicle.attitude import body_rates_from_euler_rates, dcm_body_to_nav_numpy


@dataclass(frozen=True)
class MotionPlan:
    """Piecewise-constant rates: segment k lasts ``durations[k]`` s with the given rates (rad/s)."""

    start_enu: tuple[float, float, float]
    speed: float
    yaw0: float  # Eq. 5 yaw at t=0, rad (0 = north, +pi/2 = west)
    durations: np.ndarray
    pitch_rates: np.ndarray
    yaw_rates: np.ndarray
    pitch0: float = 0.0

    @property
    def duration(self) -> float:
        return float(np.sum(self.durations))


@dataclass
class Truth:
    """True motion sampled at the IMU rate; every array has one row per sample."""

    t: np.ndarray  # s
    pos: np.ndarray  # (n, 3) east, north, up, m
    pitch: np.ndarray  # rad
    roll: np.ndarray  # rad
    yaw: np.ndarray  # rad, Eq. 5 convention (continuous, not wrapped)
    vel_body: np.ndarray  # (n, 3) m/s, body frame (x starboard, y forward, z up)
    omega_ib: np.ndarray  # (n, 3) rad/s, mean inertial angular rate over [t_k, t_k+1)
    f_body: np.ndarray  # (n, 3) m/s^2, specific force at t_k
    latitude_rad: float

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])


def _merge_programs(pitch_prog, yaw_prog):
    """Merge two [(duration, rate)] programs into one list of (duration, pitch_rate, yaw_rate)."""
    edges = sorted(
        set(np.cumsum([0.0] + [d for d, _ in pitch_prog]).round(9))
        | set(np.cumsum([0.0] + [d for d, _ in yaw_prog]).round(9))
    )
    total_p = sum(d for d, _ in pitch_prog)
    total_y = sum(d for d, _ in yaw_prog)
    if abs(total_p - total_y) > 1e-6:
        raise ValueError(f"pitch program lasts {total_p} s but yaw program {total_y} s")

    def rate_at(prog, t):
        acc = 0.0
        for d, r in prog:
            if t < acc + d - 1e-9:
                return r
            acc += d
        return prog[-1][1]

    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a > 1e-9:
            out.append((b - a, rate_at(pitch_prog, a), rate_at(yaw_prog, a)))
    return out


def lawnmower_turns(speed, legs, leg_length, spacing, first_turn, duration=None, sweep="back"):
    """Yaw program [(duration, yaw_rate)] of a lawn-mower entered from a straight approach.

    A quarter turn (``first_turn`` = "left" or "right") puts the vehicle across its
    approach direction; ``legs`` straight legs follow, joined by semicircles of
    diameter ``spacing`` that alternate in direction. With ``sweep="back"`` the first
    semicircle turns the same way as the quarter turn, so the pattern steps back
    along the approach; with ``"forward"`` it steps on ahead. If ``leg_length`` is
    None it is chosen so that the pattern lasts exactly ``duration`` seconds.
    """
    if legs < 1:
        raise ValueError("a lawn-mower needs at least one leg")
    radius = spacing / 2.0
    rate = speed / radius
    sign = 1.0 if first_turn == "left" else -1.0  # yaw is counter-clockwise positive
    quarter = (math.pi / 2.0) * radius / speed
    half = math.pi * radius / speed
    if leg_length is None:
        if duration is None:
            raise ValueError("give a leg length or a duration")
        leg_time = (duration - quarter - (legs - 1) * half) / legs
        if leg_time <= 0:
            raise ValueError(
                f"a {duration:.0f} s lawn-mower cannot fit {legs} legs at {spacing} m spacing"
            )
    else:
        leg_time = leg_length / speed
    prog = [(quarter, sign * rate), (leg_time, 0.0)]
    first_half = sign if sweep == "back" else -sign
    for k in range(legs - 1):
        s = first_half if k % 2 == 0 else -first_half
        prog += [(half, s * rate), (leg_time, 0.0)]
    return prog


def paper_plan(start_enu, speed=2.0, legs=4, leg_spacing=80.0, leg_length=None,
               first_turn="left", dive_pitch_rate_deg_s=0.1, cruise_s=840.0) -> MotionPlan:
    """The paper's run (Section 4.2): 25 s north, dive, 840 s lawn-mower, climb back; 1190 s."""
    pr = math.radians(dive_pitch_rate_deg_s)
    pitch_prog = [(25.0, 0.0), (50.0, -pr), (50.0, 0.0), (50.0, pr), (cruise_s, 0.0),
                  (50.0, pr), (50.0, 0.0), (50.0, -pr), (25.0, 0.0)]
    yaw_prog = [(175.0, 0.0)] + lawnmower_turns(speed, legs, leg_length, leg_spacing,
                                                first_turn, duration=cruise_s) + [(175.0, 0.0)]
    return _plan(start_enu, speed, 0.0, pitch_prog, yaw_prog)


def vehicle_run_plan(start_enu=(1000.0, 3500.0, 0.0), speed=2.0, approach_s=340.0,
                     duration_s=750.0, legs=3, leg_spacing=80.0, first_turn="left") -> MotionPlan:
    """Analog of the paper's vehicle run (Tables 8-9): east over flat terrain, then a survey.

    The vehicle heads east at the surface; the terrain under it is flat for the first
    ~240 s and rough after (see the ``vehicle-run`` terrain layout); after
    ``approach_s`` it turns into a lawn-mower that fills the remaining time.
    """
    cruise = duration_s - approach_s
    yaw_prog = [(approach_s, 0.0)] + lawnmower_turns(speed, legs, None, leg_spacing,
                                                     first_turn, duration=cruise, sweep="forward")
    pitch_prog = [(duration_s, 0.0)]
    return _plan(start_enu, speed, -math.pi / 2.0, pitch_prog, yaw_prog)


def survey_plan(centre_en, heading_deg, leg_length, spacing, legs, depth_m, speed=2.0,
                ) -> MotionPlan:
    """A lawn-mower placed on an arbitrary map by its centre, leg heading, length and spacing.

    The vehicle starts at the beginning of the first leg and flies ``legs`` legs of
    ``leg_length`` metres along ``heading_deg`` (compass, clockwise from north) and back,
    stepping ``spacing`` metres to the right of the first leg, at constant depth.
    """
    yaw0 = -math.radians(heading_deg)
    fwd = np.array([-math.sin(yaw0), math.cos(yaw0)])
    right = np.array([fwd[1], -fwd[0]])
    width = (legs - 1) * spacing
    start = np.asarray(centre_en, float) - fwd * leg_length / 2.0 - right * width / 2.0
    radius = spacing / 2.0
    rate = speed / radius
    half = math.pi * radius / speed
    yaw_prog = [(leg_length / speed, 0.0)]
    for k in range(legs - 1):
        s = -1.0 if k % 2 == 0 else 1.0  # first turn to the right
        yaw_prog += [(half, s * rate), (leg_length / speed, 0.0)]
    total = sum(d for d, _ in yaw_prog)
    return _plan((start[0], start[1], -abs(depth_m)), speed, yaw0, [(total, 0.0)], yaw_prog)


def _plan(start_enu, speed, yaw0, pitch_prog, yaw_prog) -> MotionPlan:
    segs = _merge_programs(pitch_prog, yaw_prog)
    return MotionPlan(
        start_enu=tuple(float(x) for x in start_enu),
        speed=float(speed),
        yaw0=float(yaw0),
        durations=np.array([s[0] for s in segs]),
        pitch_rates=np.array([s[1] for s in segs]),
        yaw_rates=np.array([s[2] for s in segs]),
    )


def _angles(plan: MotionPlan, t: np.ndarray):
    """Pitch, yaw and their (right-continuous) rates at times t."""
    starts = np.concatenate([[0.0], np.cumsum(plan.durations)[:-1]])
    pitch_start = plan.pitch0 + np.concatenate([[0.0], np.cumsum(plan.durations * plan.pitch_rates)[:-1]])
    yaw_start = plan.yaw0 + np.concatenate([[0.0], np.cumsum(plan.durations * plan.yaw_rates)[:-1]])
    seg = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(starts) - 1)
    tau = t - starts[seg]
    pitch = pitch_start[seg] + plan.pitch_rates[seg] * tau
    yaw = yaw_start[seg] + plan.yaw_rates[seg] * tau
    return pitch, yaw, plan.pitch_rates[seg], plan.yaw_rates[seg]


def _velocity_enu(speed, pitch, yaw):
    ct = np.cos(pitch)
    return speed * np.stack([-ct * np.sin(yaw), ct * np.cos(yaw), np.sin(pitch)], axis=-1)


def sample_path(plan: MotionPlan, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Times and ENU positions at spacing ``dt`` (Simpson integration per interval)."""
    n = int(round(plan.duration / dt))
    t = np.arange(n + 1) * dt
    pitch, yaw, _, _ = _angles(plan, t)
    pm, ym, _, _ = _angles(plan, t[:-1] + dt / 2.0)
    v = _velocity_enu(plan.speed, pitch, yaw)
    vm = _velocity_enu(plan.speed, pm, ym)
    steps = dt / 6.0 * (v[:-1] + 4.0 * vm + v[1:])
    pos = np.empty((n + 1, 3))
    pos[0] = plan.start_enu
    pos[1:] = plan.start_enu + np.cumsum(steps, axis=0)
    return t, pos


def simulate_truth(plan: MotionPlan, imu_rate_hz: float = 100.0, latitude_deg: float = 30.0) -> Truth:
    """Sample the plan at the IMU rate, with the error-free IMU outputs.

    omega_ib is the mean body rate over each sample interval (what an integrating
    gyro reports) plus Earth rate and transport rate; f_body is the specific force
    C_n^b (a^n - g^n) at the sample time, with g from Eqs. 9-13 (flat, non-rotating
    navigation frame otherwise: Coriolis terms, ~0.03 mg here, are neglected).
    """
    dt = 1.0 / imu_rate_hz
    t, pos = sample_path(plan, dt)
    pitch, yaw, pitch_rate, yaw_rate = _angles(plan, t)
    n = t.size
    roll = np.zeros(n)
    lat = math.radians(latitude_deg)

    # mean Euler rates over [t_k, t_k+1), mapped to body rates at the interval midpoint
    dpitch = np.diff(pitch, append=pitch[-1] + pitch_rate[-1] * dt) / dt
    dyaw = np.diff(yaw, append=yaw[-1] + yaw_rate[-1] * dt) / dt
    pitch_mid = pitch + 0.5 * dpitch * dt
    wx, wy, wz = body_rates_from_euler_rates(pitch_mid, 0.0, dpitch, 0.0, dyaw)
    omega_nb = np.stack([wx, wy, wz], axis=1)

    # Earth and transport rate, n-frame, projected into the body frame
    r_n, r_e = radii_of_curvature(lat)
    v_n = _velocity_enu(plan.speed, pitch, yaw)
    w_in = np.empty((n, 3))
    w_in[:, 0] = -v_n[:, 1] / (r_n + pos[:, 2])
    w_in[:, 1] = EARTH_RATE * math.cos(lat) + v_n[:, 0] / (r_e + pos[:, 2])
    w_in[:, 2] = EARTH_RATE * math.sin(lat) + v_n[:, 0] * math.tan(lat) / (r_e + pos[:, 2])
    c_bn = dcm_body_to_nav_numpy(pitch, roll, yaw)  # (n, 3, 3) C_b^n
    omega_ib = omega_nb + np.einsum("kji,kj->ki", c_bn, w_in)

    # specific force: analytic acceleration of the ENU velocity, plus gravity reaction
    ct, st = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    acc = plan.speed * np.stack([
        st * pitch_rate * sy - ct * cy * yaw_rate,
        -st * pitch_rate * cy - ct * sy * yaw_rate,
        ct * pitch_rate,
    ], axis=1)
    acc[:, 2] += gravity(lat, pos[:, 2])
    f_body = np.einsum("kji,kj->ki", c_bn, acc)

    vel_body = np.zeros((n, 3))
    vel_body[:, 1] = plan.speed
    return Truth(t=t, pos=pos, pitch=pitch, roll=roll, yaw=yaw, vel_body=vel_body,
                 omega_ib=omega_ib, f_body=f_body, latitude_rad=lat)
