/*
 * cf_core.h: the attitude complementary filter's step in plain C99 (no Python, no allocation).
 *
 * The standalone core of cf_estimator: the same filter step as cf_estimator/core/step.py (with
 * stillness.py and bias.py), operation for operation, and the covariance model's row loop of
 * core/covariance.py. The Python modules are the specification; compiled with
 * -ffp-contract=off (no fused multiply-adds) this core gives their bits on the same libm.
 * cf_estimator/core/_kernel.c is its Python binding; a C/C++ node or a flight controller
 * compiles cf_core.c beside this header:
 *
 *     cc -std=c99 -O2 -ffp-contract=off -c cf_core.c    (link with -lm)
 *
 * Frames and units: world ENU inside (q = q_world_from_sensor, w x y z), gyro [rad/s] and
 * accelerometer [m/s^2] in the sensor frame, magnetometer in any unit (its direction and
 * relative norm are used), dt [s].
 *
 * Per sample (VQF's update):
 *     cf_params p;  cf_state s;
 *     cf_params_default(&p);
 *     cf_state_start(&s, q0, heading_known);    (q0: the initial attitude, ENU)
 *     for each sample:
 *         if (cf_update(&s, &p, gyro, accel_or_NULL, mag_or_NULL, dt, q) != CF_OK) ...
 * Over arrays (VQF's updateBatch, the same checks row by row):
 *     cf_run(&s, &p, gyro, accel, mag_or_NULL, dt, start, n, q_out, extra_out_or_NULL, &why)
 *
 * Not here (cf_estimator/core/filter.py): the initial attitude from the first accelerometer
 * and magnetometer samples, and the two bias hypotheses run side by side (the same step with
 * bias_learning_k2 = 0 in a second state, published while EVIDENCE_RATIO * its pv_var is below
 * the learning state's pv_var).
 */
#ifndef CF_CORE_H
#define CF_CORE_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* phase (step.py PHASE_*) */
#define CF_PHASE_UNINITIALIZED 0
#define CF_PHASE_STARTUP 1
#define CF_PHASE_RUNNING 2
#define CF_PHASE_RECOVERING 3
/* mag_status (step.py MAG_*) */
#define CF_MAG_NONE 0
#define CF_MAG_USED 1
#define CF_MAG_REJECTED 2
#define CF_MAG_DISABLED 3
/* values per row of cf_run's extra_out (filter.EXTRA_COLUMNS; columns: enum cf_extra_column) */
#define CF_EXTRA_COLUMNS 20
/* largest gyro component [rad/s] accepted (filter.GYRO_LIMIT_RAD_S) */
#define CF_GYRO_LIMIT_RAD_S 1e9

/* Why a sample was refused (cf_update, cf_run); its state is left as it was. */
enum cf_problem {
    CF_OK = 0,
    CF_GYRO_NOT_FINITE = 1,  /* "gyro sample is not finite" */
    CF_GYRO_BEYOND_LIMIT = 2, /* "gyro sample beyond 1e+09 rad/s" */
    CF_BAD_DT = 3            /* dt not positive and finite */
};

/* Columns of one extra_out row (filter.Extra): what the covariance model and the replay read. */
enum cf_extra_column {
    CF_X_ERROR = 0,       /* e (3): the raw tilt error [rad], sensor frame */
    CF_X_BIAS = 3,        /* b (3): the regulator's integral state [rad/s] */
    CF_X_CLIPPED = 6,     /* 1: the error was saturated */
    CF_X_PHASE = 7,       /* CF_PHASE_* */
    CF_X_AT_REST = 8,     /* 1: at rest */
    CF_X_MAG_STATUS = 9,  /* CF_MAG_* */
    CF_X_BIAS_SIGMA = 10, /* sigma of the bias estimate's error [rad/s] (bias.error_sigma) */
    CF_X_LX = 11,         /* the aperiodic unit's world-frame state, x [rad] */
    CF_X_LY = 12,         /* ... y [rad] */
    CF_X_YAW_ERROR = 13,  /* the heading channel's last error [rad] (0: no sample used) */
    CF_X_NOISE_A2 = 14,   /* the stillness blocks' accelerometer noise [m^2/s^4] */
    CF_X_GYRO_BIAS = 15,  /* the gyro-bias estimate b - up * z_m (3) [rad/s], sensor frame */
    CF_X_LOOP_K1 = 18,    /* the loop's running gain k1 [1/s] */
    CF_X_PV_VAR = 19      /* the velocity swing over g, mean square [rad^2 s^2] */
};

/* The parameters the step reads: FilterParams fields (core/params.py: units, meaning,
 * defaults) plus prefilter (aperiodic_prefilter) and ned (world_frame "ned": cf_output_q's
 * frame only; the state is ENU). Booleans are 0/1. */
typedef struct {
    double k1, k2, saturation_limit_rad, rotation_threshold_rad_s,
        acceleration_threshold_m_s2, aperiodic_time_constant_s,
        startup_duration_s, startup_k1, recovery_trigger_s, r1, r2, mag_saturation_limit_rad,
        mag_field_tolerance, rest_gyro_threshold_rad_s,
        rest_accel_threshold_m_s2, rest_window_s, bias_prior_sigma_rad_s,
        bias_learning_k2, gravity_m_s2, prefilter;
    int use_saturation, use_mag, mag_rejection, rest_bias_learning, ned;
} cf_params;

/* One parameter the step reads, by name (FilterParams's, or the view's prefilter):
 * where it is in cf_params, and whether it is an int flag (else a double). */
typedef struct {
    const char *name;
    size_t offset;
    int is_bool;
} cf_param_field;

/* Every field of cf_params but ned (the output frame), ending with {NULL, 0, 0}. */
extern const cf_param_field cf_param_fields[];

/* The filter state: the fields of core/state.py's StepState (same names, units and frames:
 * q* = q_world(ENU)_from_sensor, b* the integral state [rad/s, sensor], ...). Read it freely;
 * write only what ComplementaryFilter writes (cf_state_start, the aiding's hooks). */
typedef struct {
    double qw, qx, qy, qz, bx, by, bz, lx, ly, lz, rxx, rxy, rxz, ryx, ryy, ryz, rzx,
        rzy, rzz, z_m, time_s, clip_timer_s,
        rest_timer_s, blk_n, blk_t, blk_gx, blk_gy, blk_gz, blk_ax, blk_ay, blk_az, blk_g2, blk_a2,
        prev_n, pgx, pgy, pgz, pax, pay, paz, blk_d, last_n, lgx, lgy, lgz, lax, lay, laz,
        noise_g2, noise_a2, bias_var, bias_err_var, blk_mx, blk_my, blk_mz, blk_mn, pmx, pmy, pmz, pm_n,
        blk_m2, blk_md, lmx, lmy, lmz, noise_m2,
        mag_clip_timer_s, mag_ref_norm, mag_ref_dip, mag_ref_count,
        mag_last_time_s, mvx, mvy, mvz, mcx, mcy, mcz, mmx, mmy, mmz, mag_cand_norm, mag_seen_time_s,
        mag_ok_timer_s, mag_cand_timer_s, mag_ref_time_s, g_ref, accel_hold, acx, acy, acz, rate_lp, ex, ey,
        ez, error_norm,
        fx, fy, fz, yaw_error_rad, recovery_count, quick_until_s, pvx, pvy, pv_var,
        turn_rate_lp, turn_hold, loop_k1;
    char recovering, at_rest, mag_disturbed, heading_initialized, clipped, accel_used, moved,
        bias_unverified, mag_recovering, aided, mag_on_body;
    int mag_status, phase;
} cf_state;

/* A named constant of the step (step.py's name and value), for printing and checking. */
typedef struct {
    const char *name;
    double value;
    int is_count; /* an integer count (else a float) */
} cf_constant;

/* The step's named constants, ending with {NULL, 0, 0}. */
extern const cf_constant cf_constants[];

/* FilterParams() defaults (core/params.py), ENU output. */
void cf_params_default(cf_params *p);

/* The state before any sample (StepState(0, False)): q identity, nothing learned. */
void cf_state_init(cf_state *s);

/* cf_state_init, then start from the attitude q_enu (w, x, y, z; normalised here) in the
 * start-up phase, as ComplementaryFilter.initialize does for each hypothesis; heading_known:
 * the heading came from a magnetometer (else the first usable sample sets it). */
void cf_state_start(cf_state *s, const double *q_enu, int heading_known);

/* One step of the filter (step.py step()): no checks. gyro [rad/s] finite; accel [m/s^2] and
 * mag NULL when absent, else valid (cf_valid3); dt > 0 [s]. */
void cf_step(cf_state *s, const cf_params *p, const double *gyro, const double *accel,
             const double *mag, double dt);

/* One sample as ComplementaryFilter.update once initialised: CF_OK, or why it was refused
 * (gyro not finite or beyond CF_GYRO_LIMIT_RAD_S, dt not positive and finite; the state is
 * untouched). accel/mag NULL or invalid (cf_valid3): skipped for this step. q_out (4, may be
 * NULL): the attitude afterwards in the output frame (cf_output_q). */
int cf_update(cf_state *s, const cf_params *p, const double *gyro, const double *accel,
              const double *mag, double dt, double *q_out);

/* cf_update for rows start..n-1 of C-contiguous arrays: gyro (n, 3), accel and mag (n, 3) or
 * NULL (none), dt (n); writes q_out (n, 4) and, if not NULL, extra_out (n, CF_EXTRA_COLUMNS)
 * for each row it runs. Returns -1 when every row ran, else the first row refused (*problem,
 * if not NULL, says why; that row and the later ones are not run and not written). */
ptrdiff_t cf_run(cf_state *s, const cf_params *p, const double *gyro, const double *accel,
                 const double *mag, const double *dt, ptrdiff_t start, ptrdiff_t n,
                 double *q_out, double *extra_out, int *problem);

/* The two bias hypotheses (filter.py ComplementaryFilter, docs/filter.md "Two bias
 * hypotheses"): the same filter with in-flight learning (`learning`, parameters p) and without
 * it (`null`, parameters cf_params_null(p)) run on every sample; the null one is published
 * while CF_EVIDENCE_RATIO * its pv_var (the velocity swing it implies) < the learning one's. */
#define CF_EVIDENCE_RATIO 2.0

/* p with bias_learning_k2 = 0: the null hypothesis's parameters. */
void cf_params_null(const cf_params *p, cf_params *out);

/* 1 when the null hypothesis is the one to publish after this sample, else 0. */
int cf_publishes_null(const cf_state *learning, const cf_state *null);

/* cf_update of both hypotheses (both or neither: the same checks); q_out (may be NULL): the
 * published one's attitude; *published_null (may be NULL): which. */
int cf_update_pair(cf_state *learning, const cf_params *p, cf_state *null, const cf_params *pn,
                   const double *gyro, const double *accel, const double *mag, double dt,
                   double *q_out, int *published_null);

/* cf_step of both hypotheses (no checks: cf_step's inputs); returns cf_publishes_null after
 * it (1: the null one is published). */
int cf_step_pair(cf_state *learning, const cf_params *p, cf_state *null, const cf_params *pn,
                 const double *gyro, const double *accel, const double *mag, double dt);

/* cf_run of both hypotheses, each row's q_out and extra_out from the one published after it;
 * *published_null (may be NULL): which, after the last row run. */
ptrdiff_t cf_run_pair(cf_state *learning, const cf_params *p, cf_state *null,
                      const cf_params *pn, const double *gyro, const double *accel,
                      const double *mag, const double *dt, ptrdiff_t start, ptrdiff_t n,
                      double *q_out, double *extra_out, int *problem, int *published_null);

/* q in the output frame (ENU as is; NED = q_ned_from_enu * q when p->ned). */
void cf_output_q(const cf_state *s, int ned, double *q_out);

/* One extra_out row (CF_EXTRA_COLUMNS values, enum cf_extra_column) of the state. */
void cf_write_extra(const cf_state *s, double *row);

/* 1 when v is three finite values with a non-zero finite squared norm (filter.valid_vector). */
int cf_valid3(const double *v);

/* CF_OK, CF_GYRO_NOT_FINITE or CF_GYRO_BEYOND_LIMIT for a gyro sample. */
int cf_gyro_problem(const double *gyro);

/* ---- the orientation covariance model (core/covariance.py OrientationCovariance) -------- */

/* Its settings: k1 (the configured loop gain), bias_prior [rad/s], inv_6g2 = 1/(6 g^2),
 * tilt0, yaw0, yaw_unref [rad^2] (the floors and the unreferenced yaw variance), tilt_cap,
 * yaw_cap [rad^2] (the caps), yaw_memory [s]; the order of covariance_rows' consts. */
typedef struct {
    double k1, bias_prior, inv_6g2, tilt0, yaw0, yaw_unref, tilt_cap, yaw_cap, yaw_memory;
} cf_cov_consts;

/* Its memory between rows (OrientationCovariance's _clip_s, _ms, ...; all 0 at first). */
typedef struct {
    double clip_s, ms, yaw_err, cx, cy, sx, sy, yaw_lp, yaw_gap;
} cf_cov_state;

/* One column of n doubles, `stride` bytes apart (a column of a row-major array will do). */
typedef struct {
    const double *data;
    ptrdiff_t stride;
} cf_column;

/* The per-row inputs of OrientationCovariance.steps; clipped, mag_used, mag_rejected non-zero
 * = true; bias_sigma NaN = the prior; mag_age.data NULL = never (Python's None). */
typedef struct {
    cf_column dt, clipped, bias_sigma, phase, error_norm, lx, ly, noise_a2, yaw_error, mag_used,
        mag_age, loop_k1, mag_rejected;
} cf_cov_rows;

/* OrientationCovariance.steps over n rows, the same operations in the same order: tilt and
 * yaw variances [rad^2] into tilt_out, yaw_out (n each, `out_stride` bytes apart).
 * heading_initialized: a magnetometer sample has set the heading. Returns -1, the state
 * advanced past the rows; else the row whose yaw_err^2 overflows (Python's OverflowError),
 * the state left as it was (the output rows before it written). */
ptrdiff_t cf_covariance_rows(const cf_cov_consts *c, cf_cov_state *state,
                             int heading_initialized, const cf_cov_rows *in, ptrdiff_t n,
                             double *tilt_out, ptrdiff_t tilt_stride, double *yaw_out,
                             ptrdiff_t yaw_stride);

#ifdef __cplusplus
}
#endif

#endif /* CF_CORE_H */
