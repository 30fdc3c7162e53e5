"""Layout of the flat float64 parameter vector the compiled kernels read (``ClutchModel.vector()``).

Plant mechanisms own one slot each (0 = off); the mechanism objects
(``clutch_model.plant.mechanisms``) name the slot they write.
"""
R_OUTER, R_INNER, N_FRICTION, N_SEPARATOR, A_RED = 0, 1, 2, 3, 4
SIGMA, YOUNGS, ASP_DENSITY, ASP_RADIUS, K_PERM, LINING_D, BJ_CHI = 5, 6, 7, 8, 9, 10, 11
ALPHA0, ALPHA1 = 12, 13
PLATE_HEAT_CAPACITY, B1, B2, B3, B4, HTF_MIN = 14, 15, 16, 17, 18, 19
FRICTION_I = 20
FRICTION_A = 21  # a0..a19 at 21..40
H0 = 41
LOCK_SLIP = 42
# plant mechanisms (0 = off)
LAG_TAU_S, HYST_RATIO, PRELOAD_N, ENERGY_SCALE_J, DRAG_COEFF = 43, 44, 45, 46, 47
# discovered terms (mechanism `discovered`): count, then MAX_DISCOVERED_TERMS slots of
# DISC_SLOT floats: kind (1 friction multiplier, 2 additive torque), signal a, signal b
# (kernels.SIG_*; 0 = none), low-pass time constant tau_s (0 = none), coefficient
DISC_N = 48
DISC_SLOTS = 49
DISC_SLOT = 5
MAX_DISCOVERED_TERMS = 6
N_PARAMS = DISC_SLOTS + DISC_SLOT * MAX_DISCOVERED_TERMS

N_FRICTION_COEFFS = 20
DEFAULT_LOCK_SLIP_RAD_S = 1e-3



# signals the discovered terms are built from (clutch_model.discovery.terms names them) and
# the two kinds of term (a multiplier on mu_f, an additive torque); the kernels read these
(SIG_NONE, SIG_PRESSURE, SIG_PACK_TEMP, SIG_SLIP_ABS, SIG_SLIP_POWER, SIG_ENERGY,
 SIG_FORCE_RATE, SIG_SIN_ANGLE, SIG_COS_ANGLE, SIG_SLIP, SIG_SLIP_SIGN, SIG_SLIP_RATE) = range(12)
TERM_FRICTION, TERM_TORQUE = 1, 2
