"""Every numerical tolerance muvsim uses, in one place.

All set operations, membership tests, QP feasibility checks and geometric
collision tests read their tolerances from here, so that a change of policy
is one edit and every test states which constant it relies on.
"""

#: Slack in a half-space test ``a @ x <= b + MEMBERSHIP_TOL`` for a point.
#: Membership is decided on normalised rows (``|a| = 1``), so this is a
#: distance in the state's units (m, m/s, ...).  Round-off in set synthesis
#: is ~1e-12; 1e-9 keeps a margin of three decades.
MEMBERSHIP_TOL = 1e-9

#: Slack for set containment ``P <= Q`` decided through support functions.
CONTAINMENT_TOL = 1e-7

#: Two normalised half-spaces closer than this (in normal and offset) are
#: the same facet when removing redundancy.
FACET_MERGE_TOL = 1e-9

#: A row ``a @ x <= b`` is redundant when its LP maximum is below
#: ``b - REDUNDANCY_TOL``... is kept when it is tight within this slack.
REDUNDANCY_TOL = 1e-9

#: A polytope whose Chebyshev radius is below this is treated as empty or
#: lower dimensional.
EMPTY_RADIUS_TOL = 1e-9

#: Constraint-violation tolerance accepted from a QP solver's answer
#: (scaled rows).  daqp answers to ~1e-14; proxsuite to its eps_abs.
QP_FEAS_TOL = 1e-7

#: proxsuite absolute accuracy and primal-infeasibility threshold.
PROXSUITE_EPS_ABS = 1e-9
PROXSUITE_EPS_PRIMAL_INF = 1e-9

#: Two solvers agree on an optimal input when they differ by less than this
#: (m/s^2 or m/s^3).  Strictly convex 1-2 variable QPs: answers are unique.
SOLVER_AGREEMENT_TOL = 1e-5

#: proxsuite's answers agree with the exact minimiser only to this (m/s^2): on these
#: ill-conditioned 2-variable QPs (Hessian B'B ~ 1e-2) it stops at feasible points up to
#: 1.7e-2 away in paper mode (measured: drag model; 1.5e-3 on the car class), and up to 4.7e-2
#: in authority mode, where the across factor keeps its own, smaller tube (bus, across level 7:
#: proxsuite -0.4534, exact and daqp -0.4068 m/s^2, with eps_abs 1e-6 .. 1e-10 alike).  Tighter
#: eps_abs does not help and scaling the cost makes it report false infeasibility.  Its answers
#: are still checked feasible; the default solver is the exact one, and daqp agrees with it
#: within SOLVER_AGREEMENT_TOL.
PROXSUITE_AGREEMENT_TOL = 5e-2

#: Geometric separation below which two footprints count as touching (m).
#: Positive separation is required by the paper; 1e-9 m absorbs round-off.
GEOMETRY_TOL = 1e-9

#: Sorted sweeps over boxes take the candidates whose lower x lies in
#: [lo_x - widest, hi_x]; ``lo_x - widest`` may round above the lower x of a box that
#: exactly touches (hi - (hi - lo) > lo in floating point: found by hypothesis), so the
#: range starts this much lower (m).  Candidates are then tested exactly.
SWEEP_MARGIN = 1e-6

#: A vehicle whose pose is within these of the pose last sent to SUMO is not moved
#: again (``moveToXY`` is the largest of muvsim's SUMO costs; about half of a dense
#: fleet stands still, jittering by the disturbance): SUMO holds it at speed 0 instead.
#: SUMO's pose then lags muvsim's by at most 1 cm and 0.005 rad (3 cm at the ends of a
#: 12 m bus), far below the separations the traffic manager keeps.
HOLD_TOL_M = 0.01
HOLD_TOL_RAD = 0.005

#: Slack used when verifying invariance / one-step properties by LP.
VERIFY_TOL = 1e-7

#: Outward rounding of the movement-authority tables g_m(w), h_m(w) (m): g is raised and h
#: lowered by this after computing them from the polygon's vertices (the edge interpolation
#: at v = w rounds at ~1e-14 relative on values <= ~200 m).
AUTHORITY_TABLE_TOL = 1e-6

#: A speed bound (lane limit, curve speed; m/s) counts as binding when it lies this far below
#: the class's speed bound; the tube index then keeps the slack the bound needs
#: (:meth:`bridge.groups._Group.slack`).
SPEED_BOUND_TOL = 1e-6

#: Outward margin (m/s) on the velocity bounds at which the reach claims read the authority
#: tables (tm/reach.py: ``h`` at ``v_hi + margin``, ``g`` at ``v_lo - margin``; both tables are
#: non-increasing, so the boxes only grow).  Without it a velocity bound that sits on a grid point
#: of the tables (a disturbance at a vertex of D makes the bounds of consecutive steps coincide)
#: is read on either side of it depending on ~1e-15 of rounding, and the fresh claim of the next
#: step could exceed the shifted one by a grid step of the table (measured: 1.15 cm, a truck
#: under a constant vertex disturbance), breaking S_k(t+1) ⊆ S_{k+1}(t), which claim reuse
#: (tm/reach_cache.py) relies on.  1e-9 m/s moves a box by < 1e-7 m (table slopes < 100 s).
REACH_LOOKUP_MARGIN = 1e-9

#: SUMO's front position after ``moveToXY(keepRoute=3)`` farther than this from the one pushed
#: counts as a pose mismatch (``pose_mismatches``, a safety counter): SUMO then judges a body
#: muvsim did not plan.  SUMO keeps the exact position (measured: to ~1e-14 m); 1 cm absorbs
#: SUMO's own position validation on lane ends.
POSE_TOL_M = 0.01

#: Consecutive route points closer than this are one point when a path frame is built
#: (``controllers/path.py``; the same figure as the waypoint conditioning's duplicate test) (m).
PATH_DUP_TOL_M = 1e-9

#: A path frame (``controllers/path.py``) merges consecutive segments into one when every point
#: between the two ends lies within this of the chord between them (m).  Subsampled straights
#: deviate from their line by round-off only (~1e-13 m on coordinates of ~1e3 m), so they merge;
#: every input point lies within this of the frame's polyline.
PATH_COLLINEAR_TOL_M = 1e-9

#: Two consecutive route chords have the same body lean (``controllers/path.py``, the angle between
#: the body and the chord) when their leans differ by at most this (rad); a vertex where the lean
#: changes by more is kept when collinear runs merge.  Leans computed from SUMO's body on one lane
#: change differ by round-off (~1e-12 rad).
PATH_LEAN_TOL_RAD = 1e-6

#: Seconds a speed bound must add to a vehicle's plan to its stop point for the bound to count as
#: binding (:meth:`bridge.groups._Group.bound_slack`): any cost above float noise, since the plan's
#: whole steps round a cost below one step to none.
PLAN_SLOWER_TOL_S = 1e-6
