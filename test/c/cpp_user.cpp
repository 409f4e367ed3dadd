// A C++ user of the C core (as a ROS 2 node would be): cf_core.h included from C++, the core
// compiled as C and linked in (test/test_c_core.py). Turns 1 rad about the vertical in 2 s
// with the accelerometer level and prints q (w x y z).
#include <cstdio>

#include "cf_core.h"

int main()
{
    cf_params params;
    cf_state state;
    cf_params_default(&params);
    const double level[4] = {1.0, 0.0, 0.0, 0.0};
    cf_state_start(&state, level, 0);
    const double gyro[3] = {0.0, 0.0, 0.5}, accel[3] = {0.0, 0.0, 9.80665};
    double q[4] = {0.0, 0.0, 0.0, 0.0};
    for (int i = 0; i < 200; i++) {
        if (cf_update(&state, &params, gyro, accel, nullptr, 0.01, q) != CF_OK) return 1;
    }
    std::printf("%.17g %.17g %.17g %.17g\n", q[0], q[1], q[2], q[3]);
    return 0;
}
