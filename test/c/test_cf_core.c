/*
 * Tests of the standalone C core alone (cf_estimator/core/c/cf_core.c): no Python anywhere.
 *
 *   cc -std=c99 -Wall -Wextra -Werror -pedantic -O2 -ffp-contract=off \
 *      -I cf_estimator/core/c test/c/test_cf_core.c cf_estimator/core/c/cf_core.c -lm
 *   ./a.out               the behaviour tests: "N passed, N failed", exit status 1 on a failure
 *   ./a.out --defaults    "name value" per cf_param_fields entry of cf_params_default()
 *   ./a.out --constants   "name value" per cf_constants entry
 *
 * test/test_c_core.py builds and runs it, and compares the last two with the Python reference.
 */
#include "cf_core.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

static int passed, failed;

#define CHECK(cond, ...)                                                                       \
    do {                                                                                       \
        if (cond) {                                                                            \
            passed++;                                                                          \
        } else {                                                                               \
            failed++;                                                                          \
            printf("FAIL %s:%d: %s: ", __func__, __LINE__, #cond);                             \
            printf(__VA_ARGS__);                                                               \
            printf("\n");                                                                      \
        }                                                                                      \
    } while (0)

static const double LEVEL[4] = {1.0, 0.0, 0.0, 0.0};
static const double G = 9.80665;

/* a reproducible noise in [-1, 1) (a linear congruential generator) */
static unsigned long rng = 12345UL;
static double noise(void)
{
    rng = (rng * 1103515245UL + 12345UL) & 0x7fffffffUL;
    return (double)rng / 1073741824.0 - 1.0;
}

/* bit-equal states: the doubles as bytes, then each flag (no padding compared) */
static int same_state(const cf_state *a, const cf_state *b)
{
    return memcmp(a, b, offsetof(cf_state, recovering)) == 0 && a->recovering == b->recovering &&
           a->at_rest == b->at_rest && a->mag_disturbed == b->mag_disturbed &&
           a->heading_initialized == b->heading_initialized && a->clipped == b->clipped &&
           a->accel_used == b->accel_used && a->moved == b->moved &&
           a->bias_unverified == b->bias_unverified && a->mag_recovering == b->mag_recovering &&
           a->aided == b->aided && a->mag_on_body == b->mag_on_body &&
           a->mag_status == b->mag_status && a->phase == b->phase;
}

/* the tilt [rad] of q: the angle between its up direction and the world vertical */
static double tilt_rad(const cf_state *s)
{
    double upz = 1.0 - 2.0 * (s->qx * s->qx + s->qy * s->qy);
    return acos(upz > 1.0 ? 1.0 : (upz < -1.0 ? -1.0 : upz));
}

static void test_still_sensor_learns_a_constant_gyro_bias_and_stays_level(void)
{
    const double bias[3] = {0.01, -0.02, 0.005}, dt = 0.005; /* 200 Hz, 60 s */
    cf_params p;
    cf_state s;
    double extra[CF_EXTRA_COLUMNS], worst_tilt = 0.0;
    cf_params_default(&p);
    cf_state_start(&s, LEVEL, 0);
    for (int i = 0; i < 12000; i++) {
        double g[3], a[3];
        for (int k = 0; k < 3; k++) g[k] = bias[k] + 0.002 * noise();
        for (int k = 0; k < 3; k++) a[k] = (k == 2 ? G : 0.0) + 0.02 * noise();
        int why = cf_update(&s, &p, g, a, NULL, dt, NULL);
        if (why != CF_OK) {
            CHECK(why == CF_OK, "sample %d refused (%d)", i, why);
            return;
        }
        if (tilt_rad(&s) > worst_tilt) worst_tilt = tilt_rad(&s);
    }
    cf_write_extra(&s, extra);
    for (int k = 0; k < 3; k++)
        CHECK(fabs(extra[CF_X_GYRO_BIAS + k] - bias[k]) < 5e-4, "axis %d: bias %g, true %g", k,
              extra[CF_X_GYRO_BIAS + k], bias[k]);
    CHECK(s.at_rest == 1, "not at rest after 60 s still");
    CHECK(extra[CF_X_AT_REST] == 1.0, "extra's at_rest column %g", extra[CF_X_AT_REST]);
    CHECK(s.phase == CF_PHASE_RUNNING, "phase %d", s.phase);
    CHECK(extra[CF_X_BIAS_SIGMA] < 1e-3, "bias sigma %g", extra[CF_X_BIAS_SIGMA]);
    CHECK(worst_tilt < 0.01, "tilt reached %g rad", worst_tilt);
    CHECK(fabs(s.time_s - 60.0) < 1e-6, "time %g s", s.time_s);
}

static void test_a_constant_rate_integrates_to_its_angle(void)
{
    const double g[3] = {0.0, 0.0, 0.5}, dt = 0.01; /* about the vertical: 1 rad in 2 s */
    cf_params p;
    cf_state s;
    double q[4];
    cf_params_default(&p);
    cf_state_start(&s, LEVEL, 0);
    for (int i = 0; i < 200; i++) cf_update(&s, &p, g, NULL, NULL, dt, q);
    CHECK(fabs(q[0] - cos(0.5)) < 1e-9 && fabs(q[3] - sin(0.5)) < 1e-9 && fabs(q[1]) < 1e-12 &&
              fabs(q[2]) < 1e-12,
          "q (%.12f %.12f %.12f %.12f), expected (%.12f 0 0 %.12f)", q[0], q[1], q[2], q[3],
          cos(0.5), sin(0.5));
    CHECK(s.accel_used == 0, "accel_used without a sample");
    /* about the sensor's x axis: roll 0.3 rad in 1 s */
    const double gx[3] = {0.3, 0.0, 0.0};
    cf_state_start(&s, LEVEL, 0);
    for (int i = 0; i < 100; i++) cf_update(&s, &p, gx, NULL, NULL, dt, q);
    CHECK(fabs(q[0] - cos(0.15)) < 1e-9 && fabs(q[1] - sin(0.15)) < 1e-9,
          "q (%.12f %.12f %.12f %.12f)", q[0], q[1], q[2], q[3]);
}

static void test_a_tilt_error_is_corrected_by_the_accelerometer(void)
{
    const double roll = 0.2, g[3] = {0.0, 0.0, 0.0}, a[3] = {0.0, 0.0, G};
    const double q0[4] = {cos(0.5 * roll), sin(0.5 * roll), 0.0, 0.0};
    cf_params p;
    cf_state s;
    cf_params_default(&p);
    cf_state_start(&s, q0, 0);
    CHECK(fabs(tilt_rad(&s) - roll) < 1e-12, "start tilt %g", tilt_rad(&s));
    for (int i = 0; i < 1000; i++) cf_update(&s, &p, g, a, NULL, 0.005, NULL);
    CHECK(tilt_rad(&s) < 1e-3, "tilt %g rad after 5 s", tilt_rad(&s));
    CHECK(s.accel_used == 1, "accel_used");
}

static void test_an_invalid_accelerometer_or_magnetometer_sample_is_skipped(void)
{
    const double g[3] = {0.01, 0.02, -0.03}, good[3] = {0.1, 0.2, G};
    const double nan_a[3] = {NAN, 0.0, G}, zero[3] = {0.0, 0.0, 0.0},
                 inf_m[3] = {INFINITY, 0.0, 1.0}, huge[3] = {1e200, 1e200, 1e200};
    const double *bad[4] = {nan_a, zero, inf_m, huge};
    cf_params p;
    cf_state warm, skipped, gyro_only;
    cf_params_default(&p);
    cf_state_start(&warm, LEVEL, 0);
    for (int i = 0; i < 50; i++) cf_update(&warm, &p, g, good, NULL, 0.01, NULL);
    for (int b = 0; b < 4; b++) {
        skipped = warm;
        gyro_only = warm;
        CHECK(cf_update(&skipped, &p, g, bad[b], bad[b], 0.01, NULL) == CF_OK, "refused %d", b);
        cf_step(&gyro_only, &p, g, NULL, NULL, 0.01);
        CHECK(same_state(&skipped, &gyro_only),
              "invalid sample %d changed more than a gyro-only step", b);
        CHECK(skipped.accel_used == 0 && skipped.mag_status == CF_MAG_NONE,
              "sample %d: accel_used %d, mag_status %d", b, skipped.accel_used,
              skipped.mag_status);
    }
    CHECK(cf_valid3(good) && !cf_valid3(nan_a) && !cf_valid3(zero) && !cf_valid3(huge),
          "cf_valid3");
}

static void test_a_refused_sample_leaves_the_state_as_it_was(void)
{
    const double a[3] = {0.0, 0.0, G}, ok[3] = {0.0, 0.0, 0.1};
    const double not_finite[3] = {0.0, NAN, 0.0}, beyond[3] = {0.0, 0.0, -2e9};
    cf_params p;
    cf_state s, before;
    double q[4] = {7.0, 7.0, 7.0, 7.0};
    cf_params_default(&p);
    cf_state_start(&s, LEVEL, 0);
    cf_update(&s, &p, ok, a, NULL, 0.01, NULL);
    before = s;
    CHECK(cf_update(&s, &p, not_finite, a, NULL, 0.01, q) == CF_GYRO_NOT_FINITE, "NaN gyro");
    CHECK(cf_update(&s, &p, beyond, a, NULL, 0.01, q) == CF_GYRO_BEYOND_LIMIT, "2e9 rad/s");
    CHECK(cf_update(&s, &p, ok, a, NULL, 0.0, q) == CF_BAD_DT, "dt 0");
    CHECK(cf_update(&s, &p, ok, a, NULL, -0.01, q) == CF_BAD_DT, "dt < 0");
    CHECK(cf_update(&s, &p, ok, a, NULL, INFINITY, q) == CF_BAD_DT, "dt inf");
    CHECK(cf_update(&s, &p, ok, a, NULL, NAN, q) == CF_BAD_DT, "dt NaN");
    CHECK(same_state(&s, &before), "a refused sample changed the state");
    CHECK(q[0] == 7.0 && q[3] == 7.0, "a refused sample wrote q_out");
}

static void test_run_is_update_row_by_row_and_stops_at_the_first_bad_row(void)
{
    enum { N = 400 };
    static double gyro[N][3], acc[N][3], mag[N][3], dt[N], q_run[N][4], q_one[N][4];
    static double x_run[N][CF_EXTRA_COLUMNS], x_one[N][CF_EXTRA_COLUMNS];
    cf_params p;
    cf_state by_run, by_update;
    int why = -7;
    cf_params_default(&p);
    for (int i = 0; i < N; i++) {
        double t = 0.01 * i;
        gyro[i][0] = 0.3 * sin(t);
        gyro[i][1] = 0.2 * cos(2.0 * t);
        gyro[i][2] = 0.1;
        acc[i][0] = 0.5 * noise();
        acc[i][1] = 0.5 * noise();
        acc[i][2] = G + 0.5 * noise();
        mag[i][0] = 0.0;
        mag[i][1] = 20e-6 + 1e-7 * noise();
        mag[i][2] = -40e-6;
        dt[i] = 0.01;
    }
    acc[7][1] = NAN; /* skipped, not refused */
    mag[9][0] = INFINITY;
    cf_state_start(&by_run, LEVEL, 0);
    cf_state_start(&by_update, LEVEL, 0);
    CHECK(cf_run(&by_run, &p, gyro[0], acc[0], mag[0], dt, 0, N, q_run[0], x_run[0], &why) == -1,
          "cf_run refused a row");
    CHECK(why == CF_OK, "problem %d", why);
    for (int i = 0; i < N; i++) {
        cf_update(&by_update, &p, gyro[i], acc[i], mag[i], dt[i], q_one[i]);
        cf_write_extra(&by_update, x_one[i]);
    }
    CHECK(same_state(&by_run, &by_update), "states differ");
    CHECK(memcmp(q_run, q_one, sizeof(q_run)) == 0, "q differs");
    CHECK(memcmp(x_run, x_one, sizeof(x_run)) == 0, "extra differs");
    CHECK(by_run.heading_initialized == 1, "the magnetometer never set the heading");

    /* a bad dt at row 250: rows 250.. are neither run nor written */
    dt[250] = 0.0;
    for (int i = 0; i < N; i++) q_run[i][0] = -9.0;
    cf_state_start(&by_run, LEVEL, 0);
    CHECK(cf_run(&by_run, &p, gyro[0], acc[0], NULL, dt, 0, N, q_run[0], NULL, &why) == 250,
          "first bad row");
    CHECK(why == CF_BAD_DT, "problem %d", why);
    CHECK(q_run[249][0] != -9.0 && q_run[250][0] == -9.0 && q_run[N - 1][0] == -9.0,
          "rows written past the bad one");
    CHECK(fabs(by_run.time_s - 2.5) < 1e-9, "time %g after 250 rows", by_run.time_s);
    /* ... and a run from there on takes it up (start > 0) */
    dt[250] = 0.01;
    gyro[300][2] = NAN;
    CHECK(cf_run(&by_run, &p, gyro[0], NULL, NULL, dt, 250, N, q_run[0], NULL, &why) == 300,
          "first bad row from 250");
    CHECK(why == CF_GYRO_NOT_FINITE, "problem %d", why);
}

/* The two bias hypotheses: cf_run_pair is cf_update_pair row by row, each row the published
 * one's; a tilted start in motion on a de-biased gyro teaches the learning hypothesis a bias
 * the other does not take, and the null one's parameters differ only in bias_learning_k2. */
static void test_the_two_bias_hypotheses(void)
{
    enum { N = 6000 };
    static double gyro[N][3], acc[N][3], dt[N], q_run[N][4], q_one[N][4];
    static double x_run[N][CF_EXTRA_COLUMNS], x_one[N][CF_EXTRA_COLUMNS];
    cf_params p, pn;
    cf_state a_run, b_run, a_one, b_one;
    int why = -7, null_run = -1, null_one = -1;
    const double tilted[4] = {cos(0.05), sin(0.05), 0.0, 0.0}; /* 5.7 deg off */
    cf_params_default(&p);
    cf_params_null(&p, &pn);
    CHECK(pn.bias_learning_k2 == 0.0 && p.bias_learning_k2 > 0.0 && pn.k1 == p.k1,
          "null parameters");
    for (int i = 0; i < N; i++) {
        double t = 0.005 * i; /* 200 Hz, 30 s: a swaying, accelerating sensor, no bias */
        gyro[i][0] = 0.3 * cos(0.7 * t);
        gyro[i][1] = 0.0;
        gyro[i][2] = 0.0;
        double roll = 0.3 / 0.7 * sin(0.7 * t);
        double ay = sin(1.3 * t), az = 0.7 * sin(1.7 * t);
        acc[i][0] = 0.05 * noise();
        acc[i][1] = G * sin(roll) + ay * cos(roll) - az * sin(roll) + 0.05 * noise();
        acc[i][2] = G * cos(roll) - ay * sin(roll) + az * cos(roll) + 0.05 * noise();
        dt[i] = 0.005;
    }
    cf_state_start(&a_run, tilted, 0);
    cf_state_start(&b_run, tilted, 0);
    cf_state_start(&a_one, tilted, 0);
    cf_state_start(&b_one, tilted, 0);
    CHECK(cf_run_pair(&a_run, &p, &b_run, &pn, gyro[0], acc[0], NULL, dt, 0, N, q_run[0],
                      x_run[0], &why, &null_run) == -1 && why == CF_OK,
          "cf_run_pair refused a row");
    for (int i = 0; i < N; i++) {
        CHECK(cf_update_pair(&a_one, &p, &b_one, &pn, gyro[i], acc[i], NULL, dt[i], q_one[i],
                             &null_one) == CF_OK, "row %d", i);
        cf_write_extra(null_one ? &b_one : &a_one, x_one[i]);
        CHECK(null_one == cf_publishes_null(&a_one, &b_one), "row %d", i);
    }
    CHECK(same_state(&a_run, &a_one) && same_state(&b_run, &b_one), "states differ");
    CHECK(memcmp(q_run, q_one, sizeof(q_run)) == 0, "q differs");
    CHECK(memcmp(x_run, x_one, sizeof(x_run)) == 0, "extra differs");
    CHECK(null_run == null_one, "the published one after the last row");
    CHECK(!same_state(&a_one, &b_one), "the hypotheses never differed");
    /* the rule: the null one is published only when its swing is below 1/CF_EVIDENCE_RATIO */
    cf_state a = a_one, b = b_one;
    a.pv_var = 1.0;
    b.pv_var = 0.99 / CF_EVIDENCE_RATIO;
    CHECK(cf_publishes_null(&a, &b), "a smaller swing by more than the ratio");
    b.pv_var = 1.01 / CF_EVIDENCE_RATIO;
    CHECK(!cf_publishes_null(&a, &b), "within the ratio: the learning one");
    /* a refused row steps neither */
    double bad[3] = {NAN, 0.0, 0.0};
    cf_state a_before = a_one, b_before = b_one;
    CHECK(cf_update_pair(&a_one, &p, &b_one, &pn, bad, acc[0], NULL, 0.005, NULL, NULL) ==
          CF_GYRO_NOT_FINITE, "a NaN gyro");
    CHECK(same_state(&a_one, &a_before) && same_state(&b_one, &b_before), "stepped anyway");
}

static void test_the_output_frame(void)
{
    cf_state s;
    double q[4], h = sqrt(0.5);
    cf_state_init(&s);
    cf_output_q(&s, 0, q);
    CHECK(q[0] == 1.0 && q[1] == 0.0 && q[2] == 0.0 && q[3] == 0.0, "ENU identity");
    cf_output_q(&s, 1, q); /* NED: q_ned_from_enu = (0, h, h, 0) */
    CHECK(q[0] == 0.0 && q[1] == h && q[2] == h && q[3] == 0.0, "NED (%g %g %g %g)", q[0], q[1],
          q[2], q[3]);
}

static void test_covariance_rows(void)
{
    enum { N = 50 };
    static double dt[N], zero[N], phase[N], en[N], lx[N], noise_a2[N], ye[N], used[N], k1[N];
    static double tilt[N], yaw[N], sigma[N];
    cf_cov_consts c = {0.35, 0.1, 1.0 / (6.0 * G * G), 1e-4, 3e-4, 10.0, 9.8696, 10.0, 30.0};
    cf_cov_state st, before;
    cf_cov_rows in;
    cf_column none = {NULL, 0};
    for (int i = 0; i < N; i++) {
        dt[i] = 0.01;
        phase[i] = CF_PHASE_RUNNING;
        en[i] = 0.01;
        lx[i] = 0.001;
        noise_a2[i] = 0.01;
        ye[i] = 0.02;
        used[i] = 1.0;
        k1[i] = 0.35;
        sigma[i] = NAN; /* the prior */
    }
#define COL(a) {a, sizeof(double)}
    cf_column cdt = COL(dt), czero = COL(zero), cph = COL(phase), cen = COL(en), clx = COL(lx),
              cna = COL(noise_a2), cye = COL(ye), cused = COL(used), ck1 = COL(k1),
              csig = COL(sigma);
#undef COL
    in.dt = cdt;
    in.clipped = czero;
    in.bias_sigma = csig;
    in.phase = cph;
    in.error_norm = cen;
    in.lx = clx;
    in.ly = czero;
    in.noise_a2 = cna;
    in.yaw_error = cye;
    in.mag_used = cused;
    in.mag_age = none;
    in.loop_k1 = ck1;
    in.mag_rejected = czero;
    memset(&st, 0, sizeof(st));
    CHECK(cf_covariance_rows(&c, &st, 0, &in, N, tilt, sizeof(double), yaw, sizeof(double)) == -1,
          "refused");
    CHECK(yaw[N - 1] == 10.0, "unreferenced yaw %g", yaw[N - 1]);
    CHECK(tilt[N - 1] > 1e-4 && tilt[N - 1] < 1e-3, "tilt %g", tilt[N - 1]);
    CHECK(st.yaw_gap > 0.49 && st.yaw_gap < 0.51, "yaw_gap %g", st.yaw_gap);
    CHECK(cf_covariance_rows(&c, &st, 1, &in, N, tilt, sizeof(double), yaw, sizeof(double)) == -1,
          "refused");
    CHECK(fabs(yaw[N - 1] - (3e-4 + 0.02 * 0.02)) < 1e-12, "referenced yaw %g", yaw[N - 1]);
    /* yaw_err ** 2 overflows: Python's OverflowError; the state is kept */
    ye[20] = 1e200;
    before = st;
    CHECK(cf_covariance_rows(&c, &st, 1, &in, N, tilt, sizeof(double), yaw, sizeof(double)) == 20,
          "overflow row");
    CHECK(memcmp(&st, &before, sizeof(st)) == 0, "the state changed on overflow");
}

static void print_defaults(void)
{
    cf_params p;
    cf_params_default(&p);
    for (const cf_param_field *f = cf_param_fields; f->name != NULL; f++) {
        const char *at = (const char *)&p + f->offset;
        if (f->is_bool)
            printf("%s %d\n", f->name, *(const int *)at);
        else
            printf("%s %.17g\n", f->name, *(const double *)at);
    }
    printf("ned %d\n", p.ned);
}

static void print_constants(void)
{
    for (const cf_constant *c = cf_constants; c->name != NULL; c++)
        printf("%s %.17g\n", c->name, c->value);
}

int main(int argc, char **argv)
{
    if (argc > 1 && strcmp(argv[1], "--defaults") == 0) {
        print_defaults();
        return 0;
    }
    if (argc > 1 && strcmp(argv[1], "--constants") == 0) {
        print_constants();
        return 0;
    }
    test_still_sensor_learns_a_constant_gyro_bias_and_stays_level();
    test_a_constant_rate_integrates_to_its_angle();
    test_a_tilt_error_is_corrected_by_the_accelerometer();
    test_an_invalid_accelerometer_or_magnetometer_sample_is_skipped();
    test_a_refused_sample_leaves_the_state_as_it_was();
    test_run_is_update_row_by_row_and_stops_at_the_first_bad_row();
    test_the_two_bias_hypotheses();
    test_the_output_frame();
    test_covariance_rows();
    printf("%d passed, %d failed\n", passed, failed);
    return failed != 0;
}
