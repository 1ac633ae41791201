/* Runs the no_std proof library's entry points from a C program (no Rust std anywhere in the
 * executable) and checks what each returns. Built and run by scripts/test.sh:
 *   cc ci/nostd-proof/main.c target/nostd-proof/debug/libnostd_proof.a -o target/nostd-proof/run
 */
#include <stdio.h>

int stereonav_nostd_harris_features(void);
int stereonav_nostd_stream_round_trip(void);
int stereonav_nostd_rig_round_trip(void);
int stereonav_nostd_selfcal(void);
int stereonav_nostd_tracking(void);
int stereonav_nostd_ekf(void);
int stereonav_nostd_navigator(void);

/* The precompiled `alloc` of the stable toolchain refers to the unwinding personality routine
 * although the library is built with panic = "abort", so nothing ever unwinds: an empty
 * definition satisfies the linker (the usual arrangement for no_std Rust linked from C). */
void rust_eh_personality(void) {}

static int check(const char *name, int got, int want) {
    printf("%-44s %d (want %d)\n", name, got, want);
    return got == want ? 0 : 1;
}

int main(void) {
    int failed = 0;
    failed += check("harris features", stereonav_nostd_harris_features(), 1);
    failed += check("stream round trip features", stereonav_nostd_stream_round_trip(), 2);
    failed += check("rig round trip lamps", stereonav_nostd_rig_round_trip(), 4);
    failed += check("phase-1 self-calibration recovers f", stereonav_nostd_selfcal(), 1);
    failed += check("confirmed tracks of four lamps", stereonav_nostd_tracking(), 4);
    failed += check("EKF maps four lamps and learns the baseline", stereonav_nostd_ekf(), 1);
    failed += check("navigator maps four lamps", stereonav_nostd_navigator(), 4);
    return failed == 0 ? 0 : 1;
}
