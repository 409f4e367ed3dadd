/*
 * cf_core.c: the filter step of cf_estimator/core/step.py in plain C99 (see cf_core.h).
 *
 * step.py is the reference (read it for the equations and their meaning); this file repeats its
 * arithmetic in the same order, so both give the same bits on the same libm (tested in
 * test/test_kernel.py through the Python binding, _kernel.c). Build with -ffp-contract=off: no
 * fused multiply-adds, as in Python. Squares are products, sq(x) = x * x, as in the Python
 * (ops.sq: Python's `x ** 2` calls libm's pow, which is not correctly rounded). Each stage is a
 * static function of the same name as step.py's; the constants have step.py's names and values
 * (test/test_twin_source.py reads both sources).
 */
#include "cf_core.h"

#include <math.h>
#include <string.h>

/* constants of step.py (test_twin_source.py and test_kernel.py check they agree) */
#define RATE_LOWPASS_TIME_CONSTANT_S 0.5
#define TURN_LOWPASS_TIME_CONSTANT_S 2.0
#define REST_NOISE_SIGMAS 2.0
#define ACCEL_LOWPASS_TIME_CONSTANT_S 0.05
#define ACCEL_SPIKE_SIGMAS 4.0
#define QUICK_LAG_TIME_CONSTANT_S 0.2
#define REST_SAMPLE_SIGMAS 8.0
#define REST_GATE_SIGMAS 3.0
#define REST_STILL_BLOCKS 2.0
#define BIAS_LIMIT_SIGMAS 5.0
#define REST_NOISE_CAP 1.0
#define BIAS_LEARNING_MAX_ERROR_RAD 0.35
#define BIAS_LEARNING_NOISE_SIGMAS 3.0
#define LOOP_LAG_FRACTION 0.75
#define REST_MAG_TOLERANCE_RAD 0.01
#define ACCEL_DETECT_SIGMAS 3.0
#define BIAS_RANDOM_WALK_RAD_S_SQRT_S 2e-4
#define SWING_TIME_CONSTANT_S 30.0
#define SWING_VAR_TIME_CONSTANT_S 10.0
#define GYRO_SCALE_UNCERTAINTY 0.01
#define GRAVITY_TIME_CONSTANT_S 10.0
#define MAG_REFERENCE_SAMPLES 20
#define MAG_RELEARN_AFTER_S 20.0
#define MAG_MAX_DT_S 1.0
#define MAG_SETTLE_S 3.0
#define MAG_TURN_TIME_CONSTANT_S 1.0
#define MAG_SMOOTH_TIME_CONSTANT_S 0.25
#define MAG_TURN_TOLERANCE_RAD 0.05
#define MAG_TURN_FRACTION 0.05
#define MAG_DRIFT_SIGMAS 3.0
#define MAG_CANDIDATE_NORM_TOLERANCE 0.05
#define SMALL_ANGLE_RAD 1e-6 /* ops.SMALL_ANGLE_RAD */
#define TINY 1e-300 /* ops.TINY */
#define RECOVERY_EXIT_FRACTION 0.5
#define MAG_RECOVERY_EXIT_FRACTION 0.1
#define MAG_QUICK_LIMIT_RAD 4.0
#define MAG_MIN_HORIZONTAL 1e-3
#define REST_MIN_VARIANCE 1e-12
#define SQRT3 1.7320508075688772
#define BIAS_LEARNING_MIN_K1 1e-3

/* ---- parameters, state, constants -------------------------------------------------------- */
#define DF(n) {#n, offsetof(cf_params, n), 0}
#define BF(n) {#n, offsetof(cf_params, n), 1}
const cf_param_field cf_param_fields[] = {
    DF(k1), DF(k2), DF(saturation_limit_rad),
    DF(rotation_threshold_rad_s), DF(acceleration_threshold_m_s2),
    DF(aperiodic_time_constant_s), DF(startup_duration_s), DF(startup_k1),
    DF(recovery_trigger_s), DF(r1), DF(r2), DF(mag_saturation_limit_rad),
    DF(mag_field_tolerance), DF(rest_gyro_threshold_rad_s),
    DF(rest_accel_threshold_m_s2), DF(rest_window_s),
    DF(bias_prior_sigma_rad_s), DF(bias_learning_k2), DF(gravity_m_s2),
    DF(prefilter), BF(use_saturation), BF(use_mag),
    BF(mag_rejection), BF(rest_bias_learning), {NULL, 0, 0}};
#undef DF
#undef BF

/* FilterParams() of core/params.py (test/test_c_core.py checks they agree) */
void cf_params_default(cf_params *p)
{
    memset(p, 0, sizeof(*p));
    p->k1 = 0.35;
    p->k2 = 0.005;
    p->saturation_limit_rad = 0.01;
    p->rotation_threshold_rad_s = 0.2;
    p->acceleration_threshold_m_s2 = 0.5;
    p->aperiodic_time_constant_s = 2.0;
    p->startup_duration_s = 2.0;
    p->startup_k1 = 5.0;
    p->recovery_trigger_s = 10.0;
    p->r1 = 0.07;
    p->r2 = 0.0;
    p->mag_saturation_limit_rad = 0.2;
    p->mag_field_tolerance = 0.17;
    p->rest_gyro_threshold_rad_s = 0.01;
    p->rest_accel_threshold_m_s2 = 0.2;
    p->rest_window_s = 0.5;
    p->bias_prior_sigma_rad_s = 0.1;
    p->bias_learning_k2 = 0.8;
    p->gravity_m_s2 = 9.80665;
    p->prefilter = 0.5;
    p->use_saturation = 1;
    p->use_mag = 1;
    p->mag_rejection = 1;
    p->rest_bias_learning = 1;
    p->ned = 0;
}

#define C(n) {#n, n, 0}
#define N(n) {#n, n, 1}
const cf_constant cf_constants[] = {
    C(ACCEL_LOWPASS_TIME_CONSTANT_S), C(ACCEL_SPIKE_SIGMAS), C(REST_GATE_SIGMAS),
    C(REST_NOISE_CAP), C(BIAS_LEARNING_MAX_ERROR_RAD), C(REST_MAG_TOLERANCE_RAD),
    C(ACCEL_DETECT_SIGMAS), C(REST_STILL_BLOCKS), C(BIAS_LIMIT_SIGMAS),
    C(QUICK_LAG_TIME_CONSTANT_S),
    C(RATE_LOWPASS_TIME_CONSTANT_S), C(REST_NOISE_SIGMAS), C(REST_SAMPLE_SIGMAS),
    C(BIAS_RANDOM_WALK_RAD_S_SQRT_S), C(GRAVITY_TIME_CONSTANT_S), N(MAG_REFERENCE_SAMPLES),
    C(MAG_RELEARN_AFTER_S), C(MAG_MAX_DT_S), C(MAG_SMOOTH_TIME_CONSTANT_S), C(MAG_SETTLE_S),
    C(MAG_TURN_TIME_CONSTANT_S), C(MAG_TURN_TOLERANCE_RAD), C(MAG_TURN_FRACTION),
    C(MAG_DRIFT_SIGMAS), C(MAG_CANDIDATE_NORM_TOLERANCE), C(SMALL_ANGLE_RAD),
    {"EXTRA_COLUMNS", CF_EXTRA_COLUMNS, 1}, {"EVIDENCE_RATIO", CF_EVIDENCE_RATIO, 0},
    {NULL, 0.0, 0}};
#undef C
#undef N

void cf_state_init(cf_state *s)
{
    memset(s, 0, sizeof(*s));
    s->qw = 1.0;
    s->mag_last_time_s = -1.0;
    s->mag_seen_time_s = -1.0;
    s->bias_var = -1.0;
    s->bias_err_var = -1.0;
}

/* ComplementaryFilter.initialize for one hypothesis */
void cf_state_start(cf_state *s, const double *q_enu, int heading_known)
{
    double n = sqrt(q_enu[0] * q_enu[0] + q_enu[1] * q_enu[1] + q_enu[2] * q_enu[2] +
                    q_enu[3] * q_enu[3]);
    cf_state_init(s);
    s->qw = q_enu[0] / n;
    s->qx = q_enu[1] / n;
    s->qy = q_enu[2] / n;
    s->qz = q_enu[3] / n;
    s->heading_initialized = (char)(heading_known != 0);
    s->phase = CF_PHASE_STARTUP;
}

/* ---- the step (mirrors step.py) ----------------------------------------------------------- */
static inline double maxd(double a, double b) { return a >= b ? a : b; }
static inline double sq(double x) { return x * x; } /* ops.sq */
static inline double mind(double a, double b) { return a <= b ? a : b; }

/* rest_time_s() and bias_limit_rad_s() of stillness.py: rest time [s], bias bound [rad/s] */
static double rest_time_s(const cf_params *p)
{
    return REST_STILL_BLOCKS * p->rest_window_s;
}

static double bias_limit_rad_s(const cf_params *p)
{
    return BIAS_LIMIT_SIGMAS * p->bias_prior_sigma_rad_s;
}

/* One sample as the stages read it: the inputs (acc, mag NULL when absent or invalid) and the
 * terms that depend on them and dt only, never on the state or the parameters. The stages read
 * these terms instead of computing them, so the two bias hypotheses (cf_update_pair), whatever
 * their parameters, compute them once per sample; each is the very expression step.py
 * evaluates in the stage named beside it (the same operations: the same bits). */
typedef struct {
    const double *g, *acc, *mag;
    double dt;
    double an;                   /* classify_motion: |a| */
    double mn, ux, uy, uz;       /* stillness and heading: |m|, m / |m| */
    double aw, lw, tw;           /* classify_motion: the low-passes' weights */
    double leak;                 /* regulate: the velocity swing's leak */
} sample;

/* the terms of sample (see there), each as its stage writes it */
static void sample_terms(sample *x, const double *g, const double *acc, const double *mag,
                         double dt)
{
    x->g = g;
    x->acc = acc;
    x->mag = mag;
    x->dt = dt;
    if (acc != NULL) x->an = sqrt(acc[0] * acc[0] + acc[1] * acc[1] + acc[2] * acc[2]);
    if (mag != NULL) {
        double mx = mag[0], my = mag[1], mz = mag[2];
        x->mn = sqrt(mx * mx + my * my + mz * mz);
        x->ux = mx / x->mn;
        x->uy = my / x->mn;
        x->uz = mz / x->mn;
    }
    x->aw = dt / (ACCEL_LOWPASS_TIME_CONSTANT_S + dt);
    x->lw = dt / (RATE_LOWPASS_TIME_CONSTANT_S + dt);
    x->tw = dt / (TURN_LOWPASS_TIME_CONSTANT_S + dt);
    x->leak = dt / (SWING_TIME_CONSTANT_S + dt);
}

static void mul(double aw, double ax, double ay, double az, double bw, double bx, double by,
                double bz, double *o)
{
    o[0] = aw * bw - ax * bx - ay * by - az * bz;
    o[1] = aw * bx + ax * bw + ay * bz - az * by;
    o[2] = aw * by - ax * bz + ay * bw + az * bx;
    o[3] = aw * bz + ax * by - ay * bx + az * bw;
}

static void expmap(double vx, double vy, double vz, double *o)
{
    double angle = sqrt(vx * vx + vy * vy + vz * vz);
    /* both of the half angle, always: one sincos call where the C library has it (glibc's
     * gives sin's and cos's bits; as in turn_heading) */
    double c = cos(0.5 * angle), sn = sin(0.5 * angle);
    double k = angle < SMALL_ANGLE_RAD ? 0.5 - angle * angle / 48.0 : sn / angle;
    o[0] = c;
    o[1] = k * vx;
    o[2] = k * vy;
    o[3] = k * vz;
}

static void rotate(double qw, double qx, double qy, double qz, double vx, double vy, double vz,
                   double *o)
{
    double tx = 2.0 * (qy * vz - qz * vy);
    double ty = 2.0 * (qz * vx - qx * vz);
    double tz = 2.0 * (qx * vy - qy * vx);
    o[0] = vx + qw * tx + (qy * tz - qz * ty);
    o[1] = vy + qw * ty + (qz * tx - qx * tz);
    o[2] = vz + qw * tz + (qx * ty - qy * tx);
}

/* up_direction() of step.py: the estimated up direction in the sensor frame (third row of R) */
static void up(const cf_state *s, double *v)
{
    v[0] = 2.0 * (s->qx * s->qz - s->qw * s->qy);
    v[1] = 2.0 * (s->qy * s->qz + s->qw * s->qx);
    v[2] = 1.0 - 2.0 * (s->qx * s->qx + s->qy * s->qy);
}

static void mul_into(cf_state *s, const double *d)
{
    double q[4];
    mul(s->qw, s->qx, s->qy, s->qz, d[0], d[1], d[2], d[3], q);
    s->qw = q[0];
    s->qx = q[1];
    s->qy = q[2];
    s->qz = q[3];
}

static void turn_heading(cf_state *s, double angle)
{
    /* no turn (predict's z_m = 0 without r2): cos(+-0) = 1 and sin(+-0) = +-0 exactly, as the
     * C library (C99 Annex F) and Python's math give them, without the call */
    double cw = 1.0, cz = 0.5 * angle;
    if (angle != 0.0) {
        cw = cos(0.5 * angle);
        cz = sin(0.5 * angle);
    }
    double qw = cw * s->qw - cz * s->qz, qx = cw * s->qx - cz * s->qy;
    double qy = cw * s->qy + cz * s->qx, qz = cw * s->qz + cz * s->qw;
    s->qw = qw;
    s->qx = qx;
    s->qy = qy;
    s->qz = qz;
    double c = cw * cw - cz * cz, sn = 2.0 * cw * cz;
    double lx = c * s->lx - sn * s->ly, ly = sn * s->lx + c * s->ly;
    s->lx = lx;
    s->ly = ly;
    double pvx = c * s->pvx - sn * s->pvy, pvy = sn * s->pvx + c * s->pvy;
    s->pvx = pvx;
    s->pvy = pvy;
    double rxx = c * s->rxx - sn * s->ryx, ryx = sn * s->rxx + c * s->ryx;
    double rxy = c * s->rxy - sn * s->ryy, ryy = sn * s->rxy + c * s->ryy;
    double rxz = c * s->rxz - sn * s->ryz, ryz = sn * s->rxz + c * s->ryz;
    s->rxx = rxx;
    s->ryx = ryx;
    s->rxy = rxy;
    s->ryy = ryy;
    s->rxz = rxz;
    s->ryz = ryz;
}

/* _toward_unit() of step.py: v <- normalise(v + a (u - v)) */
static void toward_unit(double *vx, double *vy, double *vz, double ux, double uy, double uz,
                        double a)
{
    double x = *vx + a * (ux - *vx), y = *vy + a * (uy - *vy), z = *vz + a * (uz - *vz);
    double n = maxd(sqrt(x * x + y * y + z * z), TINY);
    *vx = x / n;
    *vy = y / n;
    *vz = z / n;
}

/* heading() of step.py: one magnetometer sample checked against the field reference, then the
   heading correction ('yaw' or 'full' mode) */
static void heading(cf_state *s, const cf_params *p, const sample *x, int fast, int learn)
{
    double mn = x->mn, ux = x->ux, uy = x->uy, uz = x->uz; /* sample_terms */
    double w[3];
    rotate(s->qw, s->qx, s->qy, s->qz, ux, uy, uz, w);
    double horizontal = sqrt(w[0] * w[0] + w[1] * w[1]);
    double dip = atan2(-w[2], horizontal);
    double age = s->mag_last_time_s < 0.0 ? 0.0 : s->time_s - s->mag_last_time_s;
    double dt_m = mind(age, MAG_MAX_DT_S);

    double dt_s = mind(s->mag_seen_time_s < 0.0 ? 0.0 : s->time_s - s->mag_seen_time_s,
                       MAG_MAX_DT_S);
    int fresh = s->mag_seen_time_s < 0.0;
    s->mag_seen_time_s = s->time_s;

    double in_use = s->mag_last_time_s < 0.0 ? 0.0 : s->mag_last_time_s - s->mag_ref_time_s;
    int relearn = s->mag_cand_timer_s > mind(maxd(in_use, MAG_SETTLE_S), MAG_RELEARN_AFTER_S);
    if (relearn) {
        s->mag_ref_count = 0.0;
        s->mag_ref_time_s = s->time_s;
        s->mag_cand_timer_s = 0.0;
        s->mvx = s->mcx;
        s->mvy = s->mcy;
        s->mvz = s->mcz;
    }
    int learning = p->use_mag && (s->mag_ref_count < MAG_REFERENCE_SAMPLES);
    double n = s->mag_ref_count + 1;
    if (learning) {
        s->mag_ref_norm = s->mag_ref_norm + (mn - s->mag_ref_norm) / n;
        s->mag_ref_dip = s->mag_ref_dip + (dip - s->mag_ref_dip) / n;
        s->mag_ref_count = n;
    }
    double off_norm = maxd(mn / maxd(s->mag_ref_norm, TINY) - 1.0,
                           1.0 - mn / maxd(s->mag_ref_norm, TINY));
    double off_dip = maxd(dip - s->mag_ref_dip, s->mag_ref_dip - dip);
    double a = fresh ? 1.0 : dt_s / (MAG_SMOOTH_TIME_CONSTANT_S + dt_s);
    toward_unit(&s->mmx, &s->mmy, &s->mmz, ux, uy, uz, a);
    double mmx = s->mmx, mmy = s->mmy, mmz = s->mmz;
    double tol = MAG_TURN_TOLERANCE_RAD +
                 MAG_TURN_FRACTION * MAG_TURN_TIME_CONSTANT_S * s->rate_lp;
    double drift = MAG_DRIFT_SIGMAS * sqrt(maxd(s->bias_var, 0.0)) * age;
    int turned =
        sqrt(sq(mmx - s->mvx) + sq(mmy - s->mvy) + sq(mmz - s->mvz)) > tol + drift;
    int off = (off_norm > p->mag_field_tolerance) || (off_dip > p->mag_field_tolerance) || turned;
    s->mag_ok_timer_s = learning ? MAG_SETTLE_S : (turned ? 0.0 : s->mag_ok_timer_s + dt_s);
    int disturbed = p->mag_rejection && !learning && (off || (s->mag_ok_timer_s < MAG_SETTLE_S));
    s->mag_disturbed = (char)disturbed;
    double drift_c = MAG_DRIFT_SIGMAS * sqrt(maxd(s->bias_var, 0.0)) * s->mag_cand_timer_s;
    int cand_moved =
        (sqrt(sq(mmx - s->mcx) + sq(mmy - s->mcy) + sq(mmz - s->mcz)) >
         2.0 * MAG_TURN_TOLERANCE_RAD + drift_c) ||
        (maxd(mn - s->mag_cand_norm, s->mag_cand_norm - mn) >
         MAG_CANDIDATE_NORM_TOLERANCE * s->mag_cand_norm);
    int keep = disturbed && !cand_moved;
    int turned_away = s->rate_lp * s->mag_cand_timer_s > 2.0 * MAG_TURN_TOLERANCE_RAD;
    s->mag_on_body = (char)(disturbed && (s->mag_on_body || (cand_moved && turned_away)));
    s->mag_cand_timer_s = keep ? s->mag_cand_timer_s + dt_s : 0.0;
    if (!keep) {
        s->mcx = mmx;
        s->mcy = mmy;
        s->mcz = mmz;
        s->mag_cand_norm = mn;
    }
    a = fresh ? 1.0 : dt_s / (MAG_TURN_TIME_CONSTANT_S + dt_s);
    toward_unit(&s->mvx, &s->mvy, &s->mvz, ux, uy, uz, disturbed ? 0.0 : a);

    int usable = p->use_mag && !disturbed && (horizontal > MAG_MIN_HORIZONTAL);
    s->mag_status =
        p->use_mag ? (disturbed ? CF_MAG_REJECTED : CF_MAG_USED) : CF_MAG_DISABLED;
    if (usable) s->mag_last_time_s = s->time_s;
    int first = usable && !s->heading_initialized;
    s->heading_initialized = (char)(s->heading_initialized || usable);

    double yaw_error = atan2(w[0], w[1]);
    int big = maxd(yaw_error, -yaw_error) > p->mag_saturation_limit_rad;
    if (usable)
        s->mag_clip_timer_s = (big && learn && !first) ? s->mag_clip_timer_s + dt_m : 0.0;
    else if (disturbed)
        s->mag_clip_timer_s = 0.0;
    int enter = (p->recovery_trigger_s > 0.0) && (s->mag_clip_timer_s >= p->recovery_trigger_s);
    int leave = usable && (maxd(yaw_error, -yaw_error) <
                           MAG_RECOVERY_EXIT_FRACTION * p->mag_saturation_limit_rad);
    s->mag_recovering = (char)(s->mag_recovering ? !leave : enter);
    if (enter) s->mag_clip_timer_s = 0.0;
    int quick = fast || s->mag_recovering;
    double r1 = quick ? maxd(p->r1, p->startup_k1) : p->r1;
    double gain = usable ? r1 * dt_m / (1.0 + r1 * dt_m) : 0.0;
    double ldt = (usable && learn) ? dt_m : 0.0;
    double limit = quick ? MAG_QUICK_LIMIT_RAD : p->mag_saturation_limit_rad;

    s->yaw_error_rad = (usable || (disturbed && !s->mag_on_body)) ? yaw_error : 0.0;
    double yaw_c = mind(maxd(yaw_error, -limit), limit);
    double angle = first ? yaw_error : gain * yaw_c;
    s->z_m = s->z_m + (first ? 0.0 : p->r2 * ldt * yaw_c);
    turn_heading(s, angle);
}

/* _stillness() of step.py: block statistics, rest, bias from still blocks */
static void stillness(cf_state *s, const cf_params *p, const sample *x)
{
    const double *g = x->g, *a = x->acc, dt = x->dt;
    double gx = g[0], gy = g[1], gz = g[2], ax = a[0], ay = a[1], az = a[2];
    s->blk_n = s->blk_n + 1.0;
    s->blk_t = s->blk_t + dt;
    s->blk_gx = s->blk_gx + gx;
    s->blk_gy = s->blk_gy + gy;
    s->blk_gz = s->blk_gz + gz;
    s->blk_ax = s->blk_ax + ax;
    s->blk_ay = s->blk_ay + ay;
    s->blk_az = s->blk_az + az;
    double seen = s->last_n > 0.0 ? 1.0 : 0.0;
    s->blk_g2 = s->blk_g2 + seen * (sq(gx - s->lgx) + sq(gy - s->lgy) +
                                    sq(gz - s->lgz));
    s->blk_a2 = s->blk_a2 + seen * (sq(ax - s->lax) + sq(ay - s->lay) +
                                    sq(az - s->laz));
    s->blk_d = s->blk_d + seen;
    s->lgx = gx;
    s->lgy = gy;
    s->lgz = gz;
    s->lax = ax;
    s->lay = ay;
    s->laz = az;
    s->last_n = s->last_n + 1.0;
    if (x->mag != NULL) {
        double use = p->use_mag ? 1.0 : 0.0;
        double ux = x->ux, uy = x->uy, uz = x->uz; /* sample_terms */
        s->blk_mx = s->blk_mx + use * ux;
        s->blk_my = s->blk_my + use * uy;
        s->blk_mz = s->blk_mz + use * uz;
        s->blk_mn = s->blk_mn + use;
        /* its noise as the gyro's: sample-to-sample differences (across blocks) */
        double seen_m =
            use * ((s->lmx * s->lmx + s->lmy * s->lmy + s->lmz * s->lmz > 0.0) ? 1.0 : 0.0);
        s->blk_m2 = s->blk_m2 + seen_m * (sq(ux - s->lmx) + sq(uy - s->lmy) + sq(uz - s->lmz));
        s->blk_md = s->blk_md + seen_m;
        s->lmx = s->lmx + use * (ux - s->lmx);
        s->lmy = s->lmy + use * (uy - s->lmy);
        s->lmz = s->lmz + use * (uz - s->lmz);
    }
    int has_prev = s->prev_n > 0.0;
    int jump_g = sqrt(sq(gx - s->pgx) + sq(gy - s->pgy) + sq(gz - s->pgz)) >
                 (p->rest_gyro_threshold_rad_s + REST_SAMPLE_SIGMAS * sqrt(s->noise_g2));
    int jump_a = sqrt(sq(ax - s->pax) + sq(ay - s->pay) + sq(az - s->paz)) >
                 (p->rest_accel_threshold_m_s2 + REST_SAMPLE_SIGMAS * sqrt(s->noise_a2));
    if (has_prev && (jump_g || jump_a)) s->rest_timer_s = 0.0;

    if (!(s->blk_t >= p->rest_window_s)) { /* block not complete: only the rest flag */
        s->at_rest = (char)(p->rest_bias_learning && (s->rest_timer_s >= rest_time_s(p)));
        return; /* step.py runs the block-end lines below with weight 0: same values */
    }
    double n = s->blk_n;
    double mgx = s->blk_gx / n, mgy = s->blk_gy / n, mgz = s->blk_gz / n;
    double max_ = s->blk_ax / n, may = s->blk_ay / n, maz = s->blk_az / n;
    double nd = 2.0 * maxd(s->blk_d, 1.0);
    double noise_g2 = s->blk_g2 / nd, noise_a2 = s->blk_a2 / nd;
    double spread = 1.0 / n + 1.0 / maxd(s->prev_n, 1.0);
    double dg = sqrt(sq(mgx - s->pgx) + sq(mgy - s->pgy) + sq(mgz - s->pgz));
    double da = sqrt(sq(max_ - s->pax) + sq(may - s->pay) + sq(maz - s->paz));
    double tol_g = p->rest_gyro_threshold_rad_s +
                   REST_NOISE_SIGMAS * mind(sqrt(noise_g2 * spread),
                                            REST_NOISE_CAP * p->rest_gyro_threshold_rad_s);
    double tol_a = p->rest_accel_threshold_m_s2 +
                   REST_NOISE_SIGMAS * mind(sqrt(noise_a2 * spread),
                                            REST_NOISE_CAP * p->rest_accel_threshold_m_s2);
    int mag_seen = (s->blk_mn > 0.0) && (s->pm_n > 0.0);
    double bm = maxd(sqrt(s->blk_mx * s->blk_mx + s->blk_my * s->blk_my + s->blk_mz * s->blk_mz),
                     TINY);
    double umx = s->blk_mx / bm, umy = s->blk_my / bm, umz = s->blk_mz / bm;
    double dm = sqrt(sq(umx - s->pmx) + sq(umy - s->pmy) + sq(umz - s->pmz));
    double noise_m2 =
        s->blk_md > 0.0 ? s->blk_m2 / (2.0 * maxd(s->blk_md, 1.0)) : s->noise_m2;
    double spread_m = 1.0 / maxd(s->blk_mn, 1.0) + 1.0 / maxd(s->pm_n, 1.0);
    double tol_m = REST_MAG_TOLERANCE_RAD + p->rest_gyro_threshold_rad_s * s->blk_t +
                   REST_NOISE_SIGMAS * mind(sqrt(noise_m2 * spread_m),
                                            REST_NOISE_CAP * REST_MAG_TOLERANCE_RAD);
    int turned = mag_seen && (dm > tol_m);
    int steady = has_prev && (dg < tol_g) && (da < tol_a) && !turned &&
                 (sqrt(mgx * mgx + mgy * mgy + mgz * mgz) <
                  bias_limit_rad_s(p) * SQRT3);
    double r = maxd(noise_g2 / (3.0 * n), REST_MIN_VARIANCE);
    double gate = p->rest_gyro_threshold_rad_s + REST_GATE_SIGMAS * sqrt(s->bias_var + r);
    int consistent = (maxd(mgx - s->bx, s->bx - mgx) < gate) &&
                     (maxd(mgy - s->by, s->by - mgy) < gate) &&
                     (maxd(mgz - s->bz, s->bz - mgz) < gate);
    int still = steady && consistent;
    s->moved = (char)(s->moved || (has_prev && !still));
    s->rest_timer_s = still ? s->rest_timer_s + s->blk_t : 0.0;
    s->at_rest = (char)(p->rest_bias_learning && (s->rest_timer_s >= rest_time_s(p)));
    if (s->at_rest) s->bias_unverified = (char)(!s->moved && !mag_seen);
    if (s->at_rest) { /* a still block at rest measures the bias */
        double k = s->bias_var / (s->bias_var + r);
        s->bx = s->bx + k * (mgx - s->bx);
        s->by = s->by + k * (mgy - s->by);
        s->bz = s->bz + k * (mgz - s->bz);
        s->bias_var = s->bias_var - k * s->bias_var;
        s->bias_err_var = sq(1.0 - k) * s->bias_err_var + k * k * r;
    }
    if (still) {
        double gw = s->blk_t / (GRAVITY_TIME_CONSTANT_S + s->blk_t);
        s->g_ref = s->g_ref + gw * (sqrt(max_ * max_ + may * may + maz * maz) - s->g_ref);
    }
    s->noise_g2 = noise_g2;
    s->noise_a2 = noise_a2;
    s->noise_m2 = noise_m2;
    s->pgx = mgx;
    s->pgy = mgy;
    s->pgz = mgz;
    s->pax = max_;
    s->pay = may;
    s->paz = maz;
    s->prev_n = n;
    if (s->blk_mn > 0.0) {
        s->pmx = umx;
        s->pmy = umy;
        s->pmz = umz;
    }
    s->pm_n = s->blk_mn;
    s->blk_mx = s->blk_my = s->blk_mz = 0.0;
    s->blk_mn = 0.0;
    s->blk_m2 = s->blk_md = 0.0;
    s->blk_n = 0.0;
    s->blk_t = 0.0;
    s->blk_d = 0.0;
    s->blk_gx = s->blk_gy = s->blk_gz = 0.0;
    s->blk_ax = s->blk_ay = s->blk_az = 0.0;
    s->blk_g2 = s->blk_a2 = 0.0;
}

/* predict() of step.py: q <- Exp_z(z_m dt) q Exp((w - b) dt); the field directions turn along */
static void predict(cf_state *s, const double *g, double dt)
{
    double gx = g[0], gy = g[1], gz = g[2], d[4], w[3];
    expmap((gx - s->bx) * dt, (gy - s->by) * dt, (gz - s->bz) * dt, d);
    mul_into(s, d);
    turn_heading(s, s->z_m * dt);
    rotate(d[0], -d[1], -d[2], -d[3], s->mvx, s->mvy, s->mvz, w);
    s->mvx = w[0];
    s->mvy = w[1];
    s->mvz = w[2];
    rotate(d[0], -d[1], -d[2], -d[3], s->mcx, s->mcy, s->mcz, w);
    s->mcx = w[0];
    s->mcy = w[1];
    s->mcz = w[2];
    rotate(d[0], -d[1], -d[2], -d[3], s->mmx, s->mmy, s->mmz, w);
    s->mmx = w[0];
    s->mmy = w[1];
    s->mmz = w[2];
}

/* classify_motion() of step.py: stillness blocks, quick, the linear-acceleration detector,
   the rotation-rate low-pass; returns quick, *accelerating */
static int classify_motion(cf_state *s, const cf_params *p, const sample *x, const double *v,
                           int fast, int *accelerating)
{
    const double *g = x->g, *acc = x->acc, dt = x->dt;
    double gx = g[0], gy = g[1], gz = g[2];
    double ax = acc[0], ay = acc[1], az = acc[2];
    double an = x->an; /* sample_terms, as the low-passes' weights below */
    s->g_ref = s->g_ref > 0.0 ? s->g_ref : p->gravity_m_s2;
    double deviation = maxd(an - s->g_ref, s->g_ref - an);
    int spike = deviation > p->acceleration_threshold_m_s2 + ACCEL_SPIKE_SIGMAS * sqrt(s->noise_a2);
    stillness(s, p, x);
    double steady_g = sqrt(s->pax * s->pax + s->pay * s->pay + s->paz * s->paz);
    int quick = fast || (s->at_rest &&
                         (maxd(steady_g - s->g_ref, s->g_ref - steady_g) <
                          p->acceleration_threshold_m_s2) &&
                         (s->noise_a2 < sq(p->acceleration_threshold_m_s2)));
    double aw = s->last_n <= 1.0 ? 1.0 : x->aw;
    double acx = s->acx + aw * (ax - s->acx), acy = s->acy + aw * (ay - s->acy),
           acz = s->acz + aw * (az - s->acz);
    s->acx = acx;
    s->acy = acy;
    s->acz = acz;
    double an_lp = sqrt(s->acx * s->acx + s->acy * s->acy + s->acz * s->acz);
    double level = spike ? deviation : maxd(an_lp - s->g_ref, s->g_ref - an_lp);
    double hold = rest_time_s(p); /* quiet again when it could be at rest */
    double decayed = s->accel_hold * (hold / (hold + dt));
    s->accel_hold = maxd(level, decayed);
    double lp_sigma = sqrt(s->noise_a2 / 3.0 * dt / (2.0 * ACCEL_LOWPASS_TIME_CONSTANT_S + dt));
    *accelerating =
        s->accel_hold > p->acceleration_threshold_m_s2 + ACCEL_DETECT_SIGMAS * lp_sigma;
    double rate = sqrt(sq(gx - s->bx) + sq(gy - s->by) + sq(gz - s->bz));
    double lw = x->lw;
    s->rate_lp = s->rate_lp + lw * (rate - s->rate_lp);
    /* the turn: the rate about the estimated vertical v (turn_share) */
    double turn = (gx - s->bx) * v[0] + (gy - s->by) * v[1] + (gz - s->bz) * v[2];
    double tw = x->tw;
    s->turn_rate_lp = s->turn_rate_lp + tw * (turn - s->turn_rate_lp);
    /* its size held over the loop's memory 1/k1 (turn_share) */
    double memory = 1.0 / maxd(p->k1, BIAS_LEARNING_MIN_K1);
    s->turn_hold = maxd(maxd(s->turn_rate_lp, -s->turn_rate_lp),
                        s->turn_hold * (memory / (memory + dt)));
    return quick;
}

/* tilt_error() of step.py: e = (a/|g|) x g_hat into s->ex.., s->error_norm; u = a/|g|,
   v = g_hat (the up direction of the predicted q, third row of R); returns |e| */
static double tilt_error(cf_state *s, const double *acc, const double *v, double *u)
{
    double ux = acc[0] / s->g_ref, uy = acc[1] / s->g_ref, uz = acc[2] / s->g_ref;
    double vx = v[0], vy = v[1], vz = v[2];
    double ex = uy * vz - uz * vy, ey = uz * vx - ux * vz, ez = ux * vy - uy * vx;
    double en = sqrt(ex * ex + ey * ey + ez * ez);
    s->ex = ex;
    s->ey = ey;
    s->ez = ez;
    s->error_norm = en;
    u[0] = ux;
    u[1] = uy;
    u[2] = uz;
    return en;
}

/* saturate() of step.py: returns the scale of e; *limit, *tight, *clipped */
static double saturate(const cf_state *s, const cf_params *p, double en, int quick,
                       int accelerating, double *limit, int *tight, int *clipped)
{
    *tight = accelerating && (s->rate_lp < p->rotation_threshold_rad_s);
    *limit = *tight ? p->saturation_limit_rad : INFINITY; /* no clip: L = inf */
    *clipped = p->use_saturation && !quick && (en > *limit);
    return *clipped ? *limit / maxd(en, TINY) : 1.0;
}

/* bias.turn_share of bias.py: the share of the learning raise left while the vehicle turns */
static double turn_share(const cf_state *s, const cf_params *p)
{
    double k1_2 = sq(maxd(p->k1, BIAS_LEARNING_MIN_K1));
    double w = s->turn_hold;
    double share = k1_2 / (k1_2 + w * w);
    return share * share;
}

/* bias.error_sigma of bias.py: sigma of the bias estimate's error */
static double error_sigma(const cf_state *s)
{
    return sqrt(maxd(s->bias_err_var, 0.0));
}

/* What bias.loop_gain and bias.learning_gains read of the state that aperiodic() and
 * regulate() both see unchanged (the bias variances and the held turn rate: classify_motion
 * has set them, regulate changes the variances only after its gains): computed once a step
 * for both calls, where step.py computes them at each (the same operations on the same
 * values). */
typedef struct {
    double err_sigma; /* error_sigma(), loop_gain's drift */
    double sigma_b, share, turn; /* learning_gains': sqrt(bias_var), its share of the prior,
                                    turn_share() */
} gain_terms;

static void gain_terms_of(const cf_state *s, const cf_params *p, gain_terms *t)
{
    t->err_sigma = error_sigma(s);
    t->sigma_b = sqrt(maxd(s->bias_var, 0.0));
    t->share = mind(s->bias_var / sq(p->bias_prior_sigma_rad_s), 1.0);
    t->turn = turn_share(s, p);
}

/* bias.loop_gain of bias.py: the k1 the disturbance allows, sqrt(d / sigma_V), at most k1 */
static double loop_gain(const cf_state *s, const cf_params *p, const gain_terms *t)
{
    double sigma_v = maxd(sqrt(s->pv_var), TINY);
    double drift = t->err_sigma + GYRO_SCALE_UNCERTAINTY * s->rate_lp;
    return s->aided ? p->k1 : mind(p->k1, sqrt(drift / sigma_v));
}

/* bias.learning_gains of bias.py: k2 raised while the bias is uncertain, capped by the
 * velocity swing and withheld in a turn; k1 as the disturbance allows, critically damped */
static void learning_gains(const cf_state *s, const cf_params *p, const gain_terms *t,
                           double loop, double *k1, double *k2)
{
    double sigma_v = maxd(sqrt(s->pv_var), TINY);
    *k2 = maxd(p->k2, mind(p->bias_learning_k2 * t->share, t->sigma_b / sigma_v) * t->turn);
    *k1 = maxd(loop, 2.0 * sqrt(*k2));
}

/* learning_input() of step.py: R low-passed as the unit (its weight), and R-bar^T l into g */
static void learning_input(cf_state *s, const double *l, double weight, double *g)
{
    /* the products once (the same bits as ops.rotation_elements), R-bar in locals */
    double xx = s->qx * s->qx, yy = s->qy * s->qy, zz = s->qz * s->qz, xy = s->qx * s->qy,
           xz = s->qx * s->qz, yz = s->qy * s->qz, wx = s->qw * s->qx, wy = s->qw * s->qy,
           wz = s->qw * s->qz;
    double rxx = s->rxx, rxy = s->rxy, rxz = s->rxz, ryx = s->ryx, ryy = s->ryy, ryz = s->ryz,
           rzx = s->rzx, rzy = s->rzy, rzz = s->rzz;
    double w = (rxx * rxx + ryy * ryy + rzz * rzz == 0.0) ? 1.0 : weight;
    rxx = rxx + w * (1.0 - 2.0 * (yy + zz) - rxx);
    rxy = rxy + w * (2.0 * (xy - wz) - rxy);
    rxz = rxz + w * (2.0 * (xz + wy) - rxz);
    ryx = ryx + w * (2.0 * (xy + wz) - ryx);
    ryy = ryy + w * (1.0 - 2.0 * (xx + zz) - ryy);
    ryz = ryz + w * (2.0 * (yz - wx) - ryz);
    rzx = rzx + w * (2.0 * (xz - wy) - rzx);
    rzy = rzy + w * (2.0 * (yz + wx) - rzy);
    rzz = rzz + w * (1.0 - 2.0 * (xx + yy) - rzz);
    g[0] = rxx * l[0] + ryx * l[1] + rzx * l[2];
    g[1] = rxy * l[0] + ryy * l[1] + rzy * l[2];
    g[2] = rxz * l[0] + ryz * l[1] + rzz * l[2];
    s->rxx = rxx;
    s->rxy = rxy;
    s->rxz = rxz;
    s->ryx = ryx;
    s->ryy = ryy;
    s->ryz = ryz;
    s->rzx = rzx;
    s->rzy = rzy;
    s->rzz = rzz;
}

/* aperiodic() of step.py: the unit in the world frame on the saturated error; f into s->fx..,
   the learning input into g */
static void aperiodic(cf_state *s, const cf_params *p, const gain_terms *t, double scale,
                      int quick, int tight, double dt, double *f, double *g)
{
    double w[3], k1, k2;
    rotate(s->qw, s->qx, s->qy, s->qz, s->ex * scale, s->ey * scale, s->ez * scale, w);
    double lag = s->aided ? QUICK_LAG_TIME_CONSTANT_S : p->aperiodic_time_constant_s;
    learning_gains(s, p, t, loop_gain(s, p, t), &k1, &k2);
    lag = tight ? lag : mind(lag, LOOP_LAG_FRACTION / maxd(k1, TINY));
    double weight = dt / ((quick ? QUICK_LAG_TIME_CONSTANT_S : lag) + dt);
    s->lx = s->lx + weight * (w[0] - s->lx);
    s->ly = s->ly + weight * (w[1] - s->ly);
    s->lz = s->lz + weight * (w[2] - s->lz);
    double l[3];
    l[0] = quick ? w[0] : s->lx;
    l[1] = quick ? w[1] : s->ly;
    l[2] = quick ? w[2] : s->lz;
    rotate(s->qw, -s->qx, -s->qy, -s->qz, l[0], l[1], l[2], f);
    s->fx = f[0];
    s->fy = f[1];
    s->fz = f[2];
    learning_input(s, l, weight, g);
}

/* regulate() of step.py (bias.integrate inlined) */
static void regulate(cf_state *s, const cf_params *p, const gain_terms *t, const double *f,
                     const double *g, double en, const double *u, const double *v, int quick,
                     int tight, int learn, const sample *x)
{
    double dt = x->dt;
    double d[4], w[3];
    /* bias.observe_velocity_swing: the raw error integrated in the world frame */
    rotate(s->qw, s->qx, s->qy, s->qz, s->ex, s->ey, s->ez, w);
    double leak = x->leak; /* sample_terms */
    s->pvx = s->pvx + w[0] * dt - leak * s->pvx;
    s->pvy = s->pvy + w[1] * dt - leak * s->pvy;
    double sw = dt / (mind(SWING_VAR_TIME_CONSTANT_S, maxd(s->time_s, dt)) + dt);
    s->pv_var = s->pv_var + sw * (s->pvx * s->pvx + s->pvy * s->pvy - s->pv_var);
    double k1, k2, loop = loop_gain(s, p, t);
    learning_gains(s, p, t, loop, &k1, &k2);
    s->loop_k1 = maxd(loop, 2.0 * sqrt(p->k2));
    /* bias.learning_limit_rad: unaided, widened by one sample's scatter */
    double widen = BIAS_LEARNING_NOISE_SIGMAS * sqrt(s->noise_a2) / s->g_ref;
    double limit = BIAS_LEARNING_MAX_ERROR_RAD + (s->aided ? 0.0 : widen);
    int small = (en < limit) && (u[0] * v[0] + u[1] * v[1] + u[2] * v[2] > 0.0);
    double ldt = (learn && small) ? dt : 0.0;
    s->bx = s->bx - ldt * (k2 * g[0]);
    s->by = s->by - ldt * (k2 * g[1]);
    s->bz = s->bz - ldt * (k2 * g[2]);
    double k1m = maxd(k1, BIAS_LEARNING_MIN_K1);
    s->bias_var = s->bias_var / (1.0 + ldt * k2 / k1m);
    s->bias_err_var = s->bias_err_var / (1.0 + 2.0 * ldt * k2 / k1m);
    /* start-up in motion: the running mean of the accelerometer since initialisation (1/t) */
    int averaging = (s->time_s <= p->startup_duration_s) && s->moved;
    k1 = averaging ? 1.0 / maxd(s->time_s, dt) : (quick ? maxd(k1, p->startup_k1) : k1);
    double gain = k1 * dt / (1.0 + k1 * dt);
    expmap(gain * f[0], gain * f[1], gain * f[2], d);
    mul_into(s, d);
    double dec = gain * (quick ? 1.0 : (tight ? 0.0 : p->prefilter));
    s->lx = s->lx - dec * s->lx;
    s->ly = s->ly - dec * s->ly;
    s->lz = s->lz - dec * s->lz;
}

/* recover() of step.py: a clip unbroken for recovery_trigger_s is a real attitude error */
static void recover(cf_state *s, const cf_params *p, int clipped, double en, double limit,
                    int learn, double dt)
{
    s->clip_timer_s = clipped ? s->clip_timer_s + dt : 0.0;
    int enter = (p->recovery_trigger_s > 0.0) && (s->clip_timer_s >= p->recovery_trigger_s) &&
                learn;
    int leave = s->recovering && (en < RECOVERY_EXIT_FRACTION * limit);
    if (enter) s->recovery_count = s->recovery_count + 1;
    s->recovering = (char)(s->recovering ? !leave : enter);
    if (enter) s->clip_timer_s = 0.0;
    s->clipped = (char)clipped;
}

/* step() of step.py: the same stages in the same order, on one sample (sample_terms) */
static void step(cf_state *s, const cf_params *p, const sample *x)
{
    const double *g = x->g, *acc = x->acc, *mag = x->mag, dt = x->dt;
    s->time_s = s->time_s + dt;
    double walk = sq(BIAS_RANDOM_WALK_RAD_S_SQRT_S) * dt, prior = sq(p->bias_prior_sigma_rad_s);
    s->bias_var = (s->bias_var < 0.0 ? prior : s->bias_var) + walk;
    s->bias_err_var = (s->bias_err_var < 0.0 ? prior : s->bias_err_var) + walk;
    int startup = s->time_s <= p->startup_duration_s;
    int fast = startup || s->recovering || (s->time_s <= s->quick_until_s);
    int learn = !fast;

    predict(s, g, dt);
    s->clipped = 0;
    s->accel_used = acc != NULL;
    if (acc != NULL) {
        int accelerating, tight, clipped;
        double u[3], v[3], f[3], li[3], limit;
        up(s, v); /* q is the predicted one until regulate() corrects it */
        int quick = classify_motion(s, p, x, v, fast, &accelerating);
        double en = tilt_error(s, acc, v, u);
        double scale = saturate(s, p, en, quick, accelerating, &limit, &tight, &clipped);
        gain_terms t; /* the gains' terms aperiodic() and regulate() share */
        gain_terms_of(s, p, &t);
        aperiodic(s, p, &t, scale, quick, tight, dt, f, li);
        regulate(s, p, &t, f, li, en, u, v, quick, tight, learn, x);
        recover(s, p, clipped, en, limit, learn, dt);
    }
    double lim = bias_limit_rad_s(p);
    s->bx = mind(maxd(s->bx, -lim), lim);
    s->by = mind(maxd(s->by, -lim), lim);
    s->bz = mind(maxd(s->bz, -lim), lim);

    s->mag_status = p->use_mag ? CF_MAG_NONE : CF_MAG_DISABLED;
    if (mag != NULL) heading(s, p, x, fast, learn);
    double qn = sqrt(s->qw * s->qw + s->qx * s->qx + s->qy * s->qy + s->qz * s->qz);
    s->qw = s->qw / qn;
    s->qx = s->qx / qn;
    s->qy = s->qy / qn;
    s->qz = s->qz / qn;
    s->phase = s->recovering ? CF_PHASE_RECOVERING
                             : (startup ? CF_PHASE_STARTUP : CF_PHASE_RUNNING);
}

void cf_step(cf_state *s, const cf_params *p, const double *g, const double *acc,
             const double *mag, double dt)
{
    sample x;
    sample_terms(&x, g, acc, mag, dt);
    step(s, p, &x);
}

/* q in the output frame (ENU as is; NED = q_ned_from_enu ⊗ q, as filter.orientation_tuple) */
void cf_output_q(const cf_state *s, int ned, double *o)
{
    if (ned) {
        double h = sqrt(0.5);
        o[0] = -h * (s->qx + s->qy);
        o[1] = h * (s->qw + s->qz);
        o[2] = h * (s->qw - s->qz);
        o[3] = h * (s->qy - s->qx);
    } else {
        o[0] = s->qw;
        o[1] = s->qx;
        o[2] = s->qy;
        o[3] = s->qz;
    }
}

/* valid_vector(): finite, with a non-zero finite squared norm */
int cf_valid3(const double *v)
{
    double n2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    return isfinite(v[0] + v[1] + v[2]) && n2 > 0.0 && n2 < INFINITY;
}

/* the gyro checks of ComplementaryFilter.update */
int cf_gyro_problem(const double *g)
{
    if (!isfinite(g[0] + g[1] + g[2])) return CF_GYRO_NOT_FINITE;
    return fabs(g[0]) > CF_GYRO_LIMIT_RAD_S || fabs(g[1]) > CF_GYRO_LIMIT_RAD_S ||
           fabs(g[2]) > CF_GYRO_LIMIT_RAD_S ? CF_GYRO_BEYOND_LIMIT : CF_OK;
}


/* ---- per sample and over arrays (ComplementaryFilter.update / run_rows of one state) ------- */
/* the checks of cf_update: CF_OK and the sample, or why it is refused */
static int checked_sample(sample *x, const double *gyro,
                          const double *accel, const double *mag, double dt)
{
    int problem = cf_gyro_problem(gyro);
    if (problem) return problem;
    if (!(dt > 0.0 && isfinite(dt))) return CF_BAD_DT;
    sample_terms(x, gyro, (accel && cf_valid3(accel)) ? accel : NULL,
                 (mag && cf_valid3(mag)) ? mag : NULL, dt);
    return CF_OK;
}

int cf_update(cf_state *s, const cf_params *p, const double *gyro, const double *accel,
              const double *mag, double dt, double *q_out)
{
    sample x;
    int problem = checked_sample(&x, gyro, accel, mag, dt);
    if (problem) return problem;
    step(s, p, &x);
    if (q_out) cf_output_q(s, p->ned, q_out);
    return CF_OK;
}

/* the extra columns: e(3), b(3), clipped, phase, at_rest, mag_status, the bias estimate's error
 * sigma sqrt(bias_err_var) (bias.error_sigma), l_x, l_y (the aperiodic unit's world-frame state,
 * horizontal: what the accelerometer channel corrects by), yaw_error_rad (the heading channel's
 * last error, 0 when no sample was used), noise_a2 (the stillness blocks' accelerometer noise):
 * what the covariance model (core/covariance.py) reads; then the gyro-bias estimate
 * b - up*z_m (3, filter.gyro_bias_rad_s): what the replay samples; loop_k1 (the loop's running
 * gain), which the covariance model reads too; pv_var (the velocity swing: the evidence
 * filter.py weighs the bias hypotheses by) */
void cf_write_extra(const cf_state *s, double *x)
{
    x[0] = s->ex;
    x[1] = s->ey;
    x[2] = s->ez;
    x[3] = s->bx;
    x[4] = s->by;
    x[5] = s->bz;
    x[6] = s->clipped;
    x[7] = s->phase;
    x[8] = s->at_rest;
    x[9] = s->mag_status;
    x[10] = sqrt(s->bias_err_var);
    x[11] = s->lx;
    x[12] = s->ly;
    x[13] = s->yaw_error_rad;
    x[14] = s->noise_a2;
    /* the gyro-bias estimate b - up*z_m (filter.gyro_bias_rad_s), sensor frame */
    const double upx = 2.0 * (s->qx * s->qz - s->qw * s->qy);
    const double upy = 2.0 * (s->qy * s->qz + s->qw * s->qx);
    const double upz = 1.0 - 2.0 * (s->qx * s->qx + s->qy * s->qy);
    x[15] = s->bx - s->z_m * upx;
    x[16] = s->by - s->z_m * upy;
    x[17] = s->bz - s->z_m * upz;
    x[18] = s->loop_k1;
    x[19] = s->pv_var;
}

ptrdiff_t cf_run(cf_state *s, const cf_params *p, const double *gyro, const double *accel,
                 const double *mag, const double *dt, ptrdiff_t start, ptrdiff_t n,
                 double *q_out, double *extra_out, int *problem)
{
    for (ptrdiff_t i = start; i < n; i++) {
        const double *a = accel ? accel + 3 * i : NULL, *m = mag ? mag + 3 * i : NULL;
        int why = cf_update(s, p, gyro + 3 * i, a, m, dt[i], q_out + 4 * i);
        if (why) {
            if (problem) *problem = why;
            return i;
        }
        if (extra_out) cf_write_extra(s, extra_out + CF_EXTRA_COLUMNS * i);
    }
    if (problem) *problem = CF_OK;
    return -1;
}

/* ---- the two bias hypotheses (filter.py ComplementaryFilter) ---------------------------- */

void cf_params_null(const cf_params *p, cf_params *out)
{
    *out = *p;
    out->bias_learning_k2 = 0.0;
}

int cf_publishes_null(const cf_state *learning, const cf_state *null)
{
    return CF_EVIDENCE_RATIO * null->pv_var < learning->pv_var;
}

/* both hypotheses stepped on one sample; 1 when the null one is published after it */
static int step_pair(cf_state *learning, const cf_params *p, cf_state *null, const cf_params *pn,
                     const sample *x)
{
    step(learning, p, x);
    step(null, pn, x); /* the same sample's terms: they read no parameter */
    return cf_publishes_null(learning, null);
}

int cf_step_pair(cf_state *learning, const cf_params *p, cf_state *null, const cf_params *pn,
                 const double *gyro, const double *accel, const double *mag, double dt)
{
    sample x;
    sample_terms(&x, gyro, accel, mag, dt);
    return step_pair(learning, p, null, pn, &x);
}

int cf_update_pair(cf_state *learning, const cf_params *p, cf_state *null, const cf_params *pn,
                   const double *gyro, const double *accel, const double *mag, double dt,
                   double *q_out, int *published_null)
{
    sample x;
    int why = checked_sample(&x, gyro, accel, mag, dt); /* the same checks for both */
    if (why) return why;
    int use_null = step_pair(learning, p, null, pn, &x);
    if (q_out) cf_output_q(use_null ? null : learning, p->ned, q_out);
    if (published_null) *published_null = use_null;
    return CF_OK;
}

ptrdiff_t cf_run_pair(cf_state *learning, const cf_params *p, cf_state *null,
                      const cf_params *pn, const double *gyro, const double *accel,
                      const double *mag, const double *dt, ptrdiff_t start, ptrdiff_t n,
                      double *q_out, double *extra_out, int *problem, int *published_null)
{
    for (ptrdiff_t i = start; i < n; i++) {
        const double *a = accel ? accel + 3 * i : NULL, *m = mag ? mag + 3 * i : NULL;
        int use_null = 0;
        int why = cf_update_pair(learning, p, null, pn, gyro + 3 * i, a, m, dt[i],
                                 q_out + 4 * i, &use_null);
        if (why) {
            if (problem) *problem = why;
            return i;
        }
        if (published_null) *published_null = use_null;
        if (extra_out) cf_write_extra(use_null ? null : learning, extra_out + CF_EXTRA_COLUMNS * i);
    }
    if (problem) *problem = CF_OK;
    return -1;
}

/* ---- the covariance model's rows (core/covariance.py) ------------------------------------ */

/* core/covariance.py (test_twin_source checks the value) */
#define CORRECTION_WINDOW_S 10.0

#define AT(c, i) (*(const double *)((const char *)(c).data + (i) * (c).stride))

/* covariance.gyro_drift_var: the angle's variance after t [s] of gyro alone */
static double gyro_drift_var(double sigma_b, double t)
{
    const double q = BIAS_RANDOM_WALK_RAD_S_SQRT_S * BIAS_RANDOM_WALK_RAD_S_SQRT_S;
    const double known = sigma_b * sigma_b - q * t;
    return (known > 0.0 ? known : 0.0) * t * t + q * t * t * t / 3.0;
}

/* OrientationCovariance.steps over rows, the same operations in the same order */
ptrdiff_t cf_covariance_rows(const cf_cov_consts *k, cf_cov_state *state,
                             int heading_initialized, const cf_cov_rows *in, ptrdiff_t n,
                             double *tilt_out, ptrdiff_t tilt_stride, double *yaw_out,
                             ptrdiff_t yaw_stride)
{
    const double k1_cfg = k->k1, prior = k->bias_prior, inv_6g2 = k->inv_6g2, tilt0 = k->tilt0,
                 yaw0 = k->yaw0, yaw_unref = k->yaw_unref, tilt_cap = k->tilt_cap,
                 yaw_cap = k->yaw_cap, yaw_memory = k->yaw_memory;
    double clip_s = state->clip_s, ms = state->ms, yaw_err = state->yaw_err, cx = state->cx,
           cy = state->cy, sx = state->sx, sy = state->sy, yaw_lp = state->yaw_lp,
           yaw_gap = state->yaw_gap;
    const int heading = heading_initialized, ages = in->mag_age.data != NULL;
    volatile double pow_two = 2.0;
    for (ptrdiff_t i = 0; i < n; i++) {
        double *tilt_o = (double *)((char *)tilt_out + i * tilt_stride);
        double *yaw_o = (double *)((char *)yaw_out + i * yaw_stride);
        const double dt = AT(in->dt, i);
        clip_s = AT(in->clipped, i) != 0.0 ? clip_s + dt : 0.0;
        const double sb = AT(in->bias_sigma, i);
        const double sigma_b = sb == sb ? sb : prior;
        const double kr = AT(in->loop_k1, i);
        const double k1 = kr > 0.0 ? kr : k1_cfg;
        const double kdt = k1 * dt;
        const double mem = kdt / (1.0 + kdt);
        const double leak = dt / (CORRECTION_WINDOW_S + dt);
        const double lx = AT(in->lx, i), ly = AT(in->ly, i);
        sx = sx + mem * (lx - sx);
        sy = sy + mem * (ly - sy);
        const double ncx = cx + kdt * (lx - sx) - leak * cx;
        const double ncy = cy + kdt * (ly - sy) - leak * cy;
        cx = ncx;
        cy = ncy;
        ms += mem * (cx * cx + cy * cy - ms);
        const double ph = AT(in->phase, i);
        const double e_t =
            (ph == CF_PHASE_STARTUP || ph == CF_PHASE_RECOVERING) ? AT(in->error_norm, i) : 0.0;
        const double drift = gyro_drift_var(sigma_b, clip_s);
        const double noise = AT(in->noise_a2, i) * inv_6g2 * dt;
        const double tilt =
            tilt0 + e_t * e_t + drift + 0.5 * (ms + sx * sx + sy * sy + noise * k1);
        *tilt_o = tilt_cap < tilt ? tilt_cap : tilt; /* Python's min(tilt, cap) */
        yaw_gap += dt;
        if (heading) {
            if (AT(in->mag_used, i) != 0.0) {
                yaw_lp += yaw_gap / (yaw_memory + yaw_gap) * (AT(in->yaw_error, i) - yaw_lp);
                yaw_gap = 0.0;
                yaw_err = fabs(AT(in->yaw_error, i));
            } else if (AT(in->mag_rejected, i) != 0.0) {
                /* Python's max(abs(yaw_lp), abs(ye)): the first unless the second is larger */
                const double held = fabs(yaw_lp), ye = fabs(AT(in->yaw_error, i));
                yaw_err = ye > held ? ye : held;
            }
            const double age = ages ? AT(in->mag_age, i) : 0.0;
            const double yd = gyro_drift_var(sigma_b, age != 0.0 ? age : 0.0); /* age or 0.0 */
            /* yaw_err ** 2 as Python's float power: NaN kept, overflow an error, else libm's
             * pow itself (the exponent volatile: the compiler would make sq(x) x * x,
             * which differs from libm's pow in the last bit on some x) */
            const double y2 = isnan(yaw_err) ? yaw_err : pow(yaw_err, pow_two);
            if (isinf(y2) && isfinite(yaw_err)) return i; /* the state as it was */
            const double yaw = yaw0 + y2 + yd;
            *yaw_o = yaw_cap < yaw ? yaw_cap : yaw;
        } else {
            *yaw_o = yaw_unref;
        }
    }
    state->clip_s = clip_s;
    state->ms = ms;
    state->yaw_err = yaw_err;
    state->cx = cx;
    state->cy = cy;
    state->sx = sx;
    state->sy = sy;
    state->yaw_lp = yaw_lp;
    state->yaw_gap = yaw_gap;
    return -1;
}
