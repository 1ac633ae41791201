/* Runs the no_std proof library's entry points from a C program (no Rust std anywhere in the
 * executable) and checks what each returns, then runs the navigator through the C interface's
 * header (stereonav.h) in its firmware build: the heap is this program's (sn_firmware_alloc and
 * sn_firmware_free over malloc, as firmware would hand over its own allocator or pool).
 * Built and run by scripts/test.sh:
 *   cc -std=c99 -Wall -Wextra -Werror -I crates/capi/include ci/nostd-proof/main.c \
 *      target/nostd-proof/debug/libnostd_proof.a -o target/nostd-proof/run
 */
#define _POSIX_C_SOURCE 200112L
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "stereonav.h"

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

/* The firmware's memory for the library (stereonav.h): here the C library's, aligned. */
static size_t live_bytes, peak_bytes;

void *sn_firmware_alloc(size_t size, size_t align) {
    void *p = NULL;
    if (align < sizeof(void *)) {
        align = sizeof(void *);
    }
    if (posix_memalign(&p, align, size > 0 ? size : 1) != 0) {
        return NULL;
    }
    live_bytes += size;
    if (live_bytes > peak_bytes) {
        peak_bytes = live_bytes;
    }
    return p;
}

void sn_firmware_free(void *ptr, size_t size, size_t align) {
    (void)align;
    live_bytes -= size;
    free(ptr);
}

void sn_firmware_panic(const char *message, size_t len) {
    fprintf(stderr, "stereonav panicked: %.*s\n", (int)len, message);
    abort();
}

int stereonav_nostd_rig_json(uint8_t *buf, size_t cap);
int stereonav_nostd_drive_step(uint32_t k, uint64_t *t_us, double *velocity, uint8_t *packet,
                               size_t cap, size_t *packet_len);

/* The navigator through the header: the probe's drive (four lamps, 4 s) pushed as odometry
 * and the board's bytes one at a time, as a UART hands them over. Returns the landmarks mapped
 * (4), or a negative code. */
static int navigator_through_the_header(void) {
    static uint8_t rig[8192];
    static uint8_t packet[4096];
    sn_navigator *nav = NULL;
    size_t count = 0, frames = 0;
    uint32_t k;
    int rc, len = stereonav_nostd_rig_json(rig, sizeof rig);
    if (len < 0) {
        return -100;
    }
    rc = sn_navigator_new((const char *)rig, (size_t)len, &nav);
    if (rc != SN_OK) {
        return rc;
    }
    for (k = 0; k <= 400; k++) {
        uint64_t t_us;
        double v[3];
        size_t n = 0, i;
        if (stereonav_nostd_drive_step(k, &t_us, v, packet, sizeof packet, &n) != 0) {
            sn_navigator_free(nav);
            return -101;
        }
        rc = sn_navigator_push_odometry(nav, t_us, v[0], v[1], v[2]);
        for (i = 0; rc == SN_OK && i < n; i++) {
            size_t done = 0;
            rc = sn_navigator_push_stream(nav, packet + i, 1, &done);
            frames += done;
        }
        if (rc != SN_OK) {
            sn_navigator_free(nav);
            return rc;
        }
    }
    rc = sn_navigator_finish(nav);
    if (rc == SN_OK) {
        rc = sn_navigator_landmarks(nav, NULL, 0, &count);
    }
    {
        /* An error is answered, not a crash, in this build too. */
        double value, sigma;
        char message[256];
        if (sn_navigator_parameter(nav, "no_such", &value, &sigma) != SN_E_ARGUMENT ||
            sn_last_error(message, sizeof message) == 0 ||
            sn_localizer_new("x", 1, (const uint8_t *)"y", 1, NULL) != SN_E_NULL) {
            rc = -102;
        }
    }
    sn_navigator_free(nav);
    printf("navigator through stereonav.h: %lu frames taken, heap peak %lu bytes, %lu live after\n",
           (unsigned long)frames, (unsigned long)peak_bytes, (unsigned long)live_bytes);
    return rc == SN_OK ? (int)count : rc;
}

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
    failed += check("navigator through stereonav.h maps four lamps", navigator_through_the_header(), 4);
    return failed == 0 ? 0 : 1;
}
