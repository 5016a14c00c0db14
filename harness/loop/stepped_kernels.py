"""Per-step glue of the Python-stepped loop (`harness.loop.stepped_loop`) as compiled kernels
(numba-compatible; compiled by `harness.loop.fast` with every other KERNELS module).

The stepped loop calls, per control step, the plant (Python), the controller (one compiled call for the
paper's) and these two kernels for everything around them that used to be a dozen small numpy calls
(each ~0.5-3 us of interpreter and dispatch overhead):

* `stepped_state_check`: the plant-state checks (status 8 non-finite or exploding, 5 a section length
  <= 0) and the interaction force the controller sees (`sensing.force.mode`: exact or ignored).
* `stepped_after_control`: the record row's force / contact columns, the command checks (status 1
  non-finite, 4 runaway), the servo reference update (semi-implicit Euler, as
  `harness.loop.mujoco_kernels.mujoco_commands`) and the command slot of the actuation-delay ring.
* `stepped_paper_step`: for the paper's controller, both of them around its compiled step
  (`harness.loop.kernels.control_step`) in one call.

Same arithmetic, element by element, as the numpy statements they replace (the servo reference and
every recorded number are bit-identical; the sums in the checks only decide a status).
"""

from __future__ import annotations

import math

from controllers.status import ST_NONFINITE, ST_PLANT_STATE, ST_RUNAWAY, ST_SECTION_LENGTH
from harness.loop.kernels import control_step, runaway, section_collapsed, servo_reference_step


def stepped_state_check(state, exploding, Ftrue, Fctl, ignored):
    """Status of the noise-free state (16,) [q1, dq1, q2, dq2]: 8 if non-finite or |state| > exploding,
    5 if a section length q2[0:3] <= 0, else 0.  Then Fctl (4,) N <- 0 if ignored else Ftrue (4,)."""
    total = 0.0
    for i in range(state.shape[0]):
        total += state[i] * state[i]
    if not math.isfinite(total) or total > exploding * exploding:
        return ST_PLANT_STATE
    if section_collapsed(state):
        return ST_SECTION_LENGTH
    for i in range(Fctl.shape[0]):
        Fctl[i] = 0.0 if ignored else Ftrue[i]
    return 0


def stepped_after_control(st, T1, T2, u2, row, Ftrue, Fsens, cinfo, i_F, i_Fs, i_C, ref_mode, ext_ref, ref,
                          dt, sensed, cmd):
    """After the controller's step (status st): row[i_F:i_F + 4] <- Ftrue, row[i_Fs:i_Fs + 4] <- Fsens
    (both N), row[i_C:i_C + 5] <- cinfo; status 1 if T1 (2,), T2 (6,) or u2 (6,) is not finite, 4 if
    |e1| or |e2| (row's R_E1, R_E2, m, 1-norm) exceeds RUNAWAY.  If still 0: the servo reference
    ref (12,) = [q2_ref, dq2_ref] is updated (ref_mode 1: dq2_ref += u2 dt, q2_ref += dq2_ref dt;
    2: ref <- ext_ref (12,), the controller's own; 0: unchanged, torque actuation) and the command slot
    cmd (26,) <- [T1, T2, ref, sensed q2 (sensed[4:10])].  Returns the status."""
    for i in range(4):
        row[i_F + i] = Ftrue[i]
        row[i_Fs + i] = Fsens[i]
    for i in range(5):
        row[i_C + i] = cinfo[i]
    if st == 0:
        s1 = 0.0
        for i in range(T1.shape[0]):
            s1 += T1[i]
        s2 = 0.0
        for i in range(T2.shape[0]):
            s2 += T2[i]
        s3 = 0.0
        for i in range(u2.shape[0]):
            s3 += u2[i]
        if not math.isfinite(s1 + s2 + s3):
            st = ST_NONFINITE
    if st == 0 and runaway(row):
        st = ST_RUNAWAY
    if st != 0:
        return st
    if ref_mode == 1:
        servo_reference_step(ref, u2, dt)
    elif ref_mode == 2:
        for i in range(12):
            ref[i] = ext_ref[i]
    cmd[0] = T1[0]
    cmd[1] = T1[1]
    for i in range(6):
        cmd[2 + i] = T2[i]
    for i in range(12):
        cmd[8 + i] = ref[i]
    for i in range(6):
        cmd[20 + i] = sensed[4 + i]
    return 0


def stepped_paper_step(state, exploding, Ftrue, ignored, t, traj, noise, k, scale, mpk_c, spk_c, nodes,
                       weights, gains, spec, F, xd, dxd, ddxd, sensed, T1, T2, u2, deN, minfo, sinfo, row,
                       cinfo, i_F, i_Fs, i_C, ref_mode, ref, dt, cmd):
    """`stepped_state_check` (F (4,) is the controller's force input), the paper's `control_step` and
    `stepped_after_control` (ref_mode 0 or 1) in one call.  Returns (state status, step status): a
    non-zero state status means the step did not run (nothing recorded)."""
    s0 = stepped_state_check(state, exploding, Ftrue, F, ignored)
    if s0 != 0:
        return s0, 0
    st = control_step(t, state, traj, noise, k, scale, mpk_c, spk_c, nodes, weights, gains, spec, F, xd, dxd,
                      ddxd, sensed, T1, T2, u2, deN, minfo, sinfo, row)
    return 0, stepped_after_control(st, T1, T2, u2, row, Ftrue, F, cinfo, i_F, i_Fs, i_C, ref_mode, ref, ref,
                                    dt, sensed, cmd)


KERNELS = ("stepped_state_check", "stepped_after_control", "stepped_paper_step")
