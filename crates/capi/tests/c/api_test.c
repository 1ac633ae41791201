/*
 * api_test.c: every function of stereonav.h and every error it answers (C99, built with
 * -Wall -Wextra -Werror and run, under valgrind when it is installed, by
 * crates/capi/tests/c_programs.rs).
 *
 *   api_test RIG.toml MAP STREAM.bin
 *
 * RIG.toml: a rig file; MAP: a saved map made with it; STREAM.bin: the board's bytes of a
 * drive. Exits 0 when every check holds, else prints the failed checks and exits 1.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stereonav.h"

static int failures;

#define CHECK(cond)                                                                     \
    do {                                                                                \
        if (!(cond)) {                                                                  \
            fprintf(stderr, "api_test.c:%d: check failed: %s\n", __LINE__, #cond);      \
            failures++;                                                                 \
        }                                                                               \
    } while (0)

/* A call that must fail with `code` and leave a one-line message. */
#define FAILS_WITH(call, code)                                                          \
    do {                                                                                \
        char m_[512];                                                                   \
        int rc_ = (call);                                                               \
        size_t n_;                                                                      \
        if (rc_ != (code)) {                                                            \
            fprintf(stderr, "api_test.c:%d: %s returned %d, not %s\n", __LINE__, #call, \
                    rc_, #code);                                                        \
            failures++;                                                                 \
        }                                                                               \
        n_ = sn_last_error(m_, sizeof m_);                                              \
        if (n_ == 0 || strchr(m_, '\n') != NULL) {                                      \
            fprintf(stderr, "api_test.c:%d: no one-line message after %s\n", __LINE__,  \
                    #call);                                                             \
            failures++;                                                                 \
        }                                                                               \
    } while (0)

static uint8_t *read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    uint8_t *data;
    long n;
    if (f == NULL || fseek(f, 0, SEEK_END) != 0 || (n = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
        if (f != NULL) {
            fclose(f);
        }
        return NULL;
    }
    data = malloc((size_t)n + 1);
    if (data == NULL || fread(data, 1, (size_t)n, f) != (size_t)n) {
        free(data);
        fclose(f);
        return NULL;
    }
    fclose(f);
    *len = (size_t)n;
    return data;
}

static void last_error_semantics(void)
{
    char small[8], big[512];
    size_t whole;
    sn_navigator *nav = NULL;
    FAILS_WITH(sn_navigator_new("not = [a rig", 12, &nav), SN_E_RIG);
    CHECK(nav == NULL);
    whole = sn_last_error(NULL, 0);
    CHECK(whole > 0);
    CHECK(sn_last_error(big, sizeof big) == whole);
    CHECK(strlen(big) == whole);
    memset(small, 'x', sizeof small);
    CHECK(sn_last_error(small, sizeof small) == whole);
    CHECK(small[sizeof small - 1] == '\0' && strlen(small) == sizeof small - 1);
    CHECK(strncmp(small, big, sizeof small - 1) == 0);
    CHECK(sn_last_error(small, 0) == whole);
}

static void navigator(const char *rig, size_t rig_len, const uint8_t *stream, size_t stream_len)
{
    sn_navigator *nav = NULL;
    sn_pose pose;
    sn_landmark landmarks[4];
    sn_feature left[3] = {{100, 200, 5000}, {3000, 1500, 9000}, {6000, 4000, 7000}};
    sn_feature right[3] = {{90, 200, 5000}, {2980, 1500, 9000}, {5980, 4000, 7000}};
    uint8_t junk[300];
    size_t count = 99, frames = 0, i;
    double value = 0.0, sigma = 0.0;

    /* construction */
    FAILS_WITH(sn_navigator_new(NULL, 10, &nav), SN_E_NULL);
    FAILS_WITH(sn_navigator_new(rig, rig_len, NULL), SN_E_NULL);
    FAILS_WITH(sn_navigator_new("\xff\xfe garbage", 10, &nav), SN_E_RIG);
    FAILS_WITH(sn_navigator_new("{\"camera\": 3}", 13, &nav), SN_E_RIG);
    FAILS_WITH(sn_navigator_new(rig, rig_len / 2, &nav), SN_E_RIG);
    CHECK(sn_navigator_new(rig, rig_len, &nav) == SN_OK && nav != NULL);

    /* NULL handles everywhere */
    FAILS_WITH(sn_navigator_push_odometry(NULL, 1, 0.0, 0.0, 0.0), SN_E_NULL);
    FAILS_WITH(sn_navigator_push_stream(NULL, stream, 10, &frames), SN_E_NULL);
    FAILS_WITH(sn_navigator_push_frame(NULL, 1, left, 3, right, 3), SN_E_NULL);
    FAILS_WITH(sn_navigator_finish(NULL), SN_E_NULL);
    FAILS_WITH(sn_navigator_pose(NULL, &pose), SN_E_NULL);
    FAILS_WITH(sn_navigator_landmarks(NULL, landmarks, 4, &count), SN_E_NULL);
    FAILS_WITH(sn_navigator_parameter(NULL, "baseline", &value, &sigma), SN_E_NULL);
    sn_navigator_free(NULL);

    /* NULL pointers with sizes, NaN, names */
    FAILS_WITH(sn_navigator_pose(nav, NULL), SN_E_NULL);
    FAILS_WITH(sn_navigator_landmarks(nav, NULL, 4, &count), SN_E_NULL);
    FAILS_WITH(sn_navigator_landmarks(nav, landmarks, 4, NULL), SN_E_NULL);
    FAILS_WITH(sn_navigator_push_stream(nav, NULL, 10, &frames), SN_E_NULL);
    FAILS_WITH(sn_navigator_push_frame(nav, 1, NULL, 3, right, 3), SN_E_NULL);
    FAILS_WITH(sn_navigator_parameter(nav, NULL, &value, &sigma), SN_E_NULL);
    FAILS_WITH(sn_navigator_parameter(nav, "baseline", NULL, &sigma), SN_E_NULL);
    FAILS_WITH(sn_navigator_parameter(nav, "no_such_parameter", &value, &sigma), SN_E_ARGUMENT);
    FAILS_WITH(sn_navigator_parameter(nav, "\xff", &value, &sigma), SN_E_ARGUMENT);
    FAILS_WITH(sn_navigator_push_odometry(nav, 5, NAN, 0.0, 0.0), SN_E_ARGUMENT);
    FAILS_WITH(sn_navigator_push_odometry(nav, 5, 0.0, INFINITY, 0.0), SN_E_ARGUMENT);

    /* nothing yet: a pose at the origin, calibrating, no landmarks */
    CHECK(sn_navigator_pose(nav, &pose) == SN_OK && pose.phase == 0 && pose.t_us == 0);
    CHECK(sn_navigator_landmarks(nav, NULL, 0, &count) == SN_OK && count == 0);
    CHECK(sn_navigator_parameter(nav, "baseline", &value, &sigma) == SN_OK && value > 0.0);
    CHECK(sn_navigator_parameter(nav, "odom_scale", &value, &sigma) == SN_OK && value > 0.0);

    /* times out of order */
    CHECK(sn_navigator_push_odometry(nav, 1000, 0.1, 0.0, 0.0) == SN_OK);
    FAILS_WITH(sn_navigator_push_odometry(nav, 999, 0.1, 0.0, 0.0), SN_E_ORDER);
    CHECK(sn_navigator_push_frame(nav, 2000, left, 3, right, 3) == SN_OK);
    CHECK(sn_navigator_push_frame(nav, 2000, NULL, 0, NULL, 0) == SN_OK);
    FAILS_WITH(sn_navigator_push_frame(nav, 1999, left, 3, right, 3), SN_E_ORDER);

    /* junk in the byte stream: skipped and said, never a crash */
    for (i = 0; i < sizeof junk; i++) {
        junk[i] = (uint8_t)(i * 37u + 11u);
    }
    frames = 77;
    FAILS_WITH(sn_navigator_push_stream(nav, junk, sizeof junk, &frames), SN_E_STREAM);
    CHECK(frames == 0);
    CHECK(sn_navigator_push_stream(nav, junk, 0, NULL) == SN_OK);
    sn_navigator_free(nav);

    /* a real stream in odd chunks: frames are processed */
    nav = NULL;
    CHECK(sn_navigator_new(rig, rig_len, &nav) == SN_OK);
    {
        size_t done = 0, total = 0, at = 0, chunk = 1;
        while (at < stream_len) {
            size_t n = chunk < stream_len - at ? chunk : stream_len - at;
            int rc = sn_navigator_push_stream(nav, stream + at, n, &done);
            CHECK(rc == SN_OK || rc == SN_E_STREAM || rc == SN_E_ORDER);
            total += done;
            at += n;
            chunk = chunk % 97 + 13;
        }
        CHECK(total > 10);
    }
    CHECK(sn_navigator_finish(nav) == SN_OK);
    CHECK(sn_navigator_pose(nav, &pose) == SN_OK && pose.t_us > 0 && pose.phase == 1);
    CHECK(isfinite(pose.x) && isfinite(pose.cov[0]) && pose.cov[1] == pose.cov[3]);
    CHECK(sn_navigator_landmarks(nav, NULL, 0, &count) == SN_OK);
    if (count > 0) {
        size_t all = count;
        CHECK(sn_navigator_landmarks(nav, landmarks, 1, &count) == SN_OK && count == all);
        CHECK(landmarks[0].observations > 0 && landmarks[0].sigma[0] > 0.0);
    }
    sn_navigator_free(nav);
}

static void localizer(const char *rig, size_t rig_len, const uint8_t *map, size_t map_len,
                      const uint8_t *stream, size_t stream_len)
{
    sn_localizer *loc = NULL;
    sn_pose pose;
    uint8_t *damaged;
    size_t frames = 0;

    FAILS_WITH(sn_localizer_new(NULL, rig_len, map, map_len, &loc), SN_E_NULL);
    FAILS_WITH(sn_localizer_new(rig, rig_len, NULL, map_len, &loc), SN_E_NULL);
    FAILS_WITH(sn_localizer_new(rig, rig_len, map, map_len, NULL), SN_E_NULL);
    FAILS_WITH(sn_localizer_new("nope", 4, map, map_len, &loc), SN_E_RIG);
    FAILS_WITH(sn_localizer_new(rig, rig_len, map, map_len / 2, &loc), SN_E_MAP);
    FAILS_WITH(sn_localizer_new(rig, rig_len, (const uint8_t *)"hello", 5, &loc), SN_E_MAP);
    damaged = malloc(map_len);
    if (damaged != NULL) {
        memcpy(damaged, map, map_len);
        damaged[map_len - 10] ^= 0x55;
        FAILS_WITH(sn_localizer_new(rig, rig_len, damaged, map_len, &loc), SN_E_MAP);
        free(damaged);
    }
    CHECK(loc == NULL);

    FAILS_WITH(sn_localizer_push_odometry(NULL, 1, 0.0, 0.0, 0.0), SN_E_NULL);
    FAILS_WITH(sn_localizer_push_stream(NULL, stream, 1, &frames), SN_E_NULL);
    FAILS_WITH(sn_localizer_pose(NULL, &pose), SN_E_NULL);
    sn_localizer_free(NULL);

    CHECK(sn_localizer_new(rig, rig_len, map, map_len, &loc) == SN_OK && loc != NULL);
    FAILS_WITH(sn_localizer_pose(loc, NULL), SN_E_NULL);
    FAILS_WITH(sn_localizer_push_odometry(loc, 1, 0.0, NAN, 0.0), SN_E_ARGUMENT);
    CHECK(sn_localizer_push_odometry(loc, 100, 0.0, 0.0, 0.0) == SN_OK);
    FAILS_WITH(sn_localizer_push_odometry(loc, 50, 0.0, 0.0, 0.0), SN_E_ORDER);
    CHECK(sn_localizer_pose(loc, &pose) == SN_OK && pose.localized == 0);
    {
        int rc = sn_localizer_push_stream(loc, stream, stream_len, &frames);
        CHECK(rc == SN_OK || rc == SN_E_STREAM || rc == SN_E_ORDER);
        CHECK(frames > 10);
    }
    CHECK(sn_localizer_pose(loc, &pose) == SN_OK && pose.t_us > 0);
    sn_localizer_free(loc);
}

int main(int argc, char **argv)
{
    size_t rig_len = 0, map_len = 0, stream_len = 0;
    uint8_t *rig, *map, *stream;
    if (argc != 4) {
        fprintf(stderr, "usage: api_test RIG.toml MAP STREAM.bin\n");
        return 2;
    }
    rig = read_file(argv[1], &rig_len);
    map = read_file(argv[2], &map_len);
    stream = read_file(argv[3], &stream_len);
    if (rig == NULL || map == NULL || stream == NULL) {
        fprintf(stderr, "api_test: cannot read the inputs\n");
        free(rig);
        free(map);
        free(stream);
        return 2;
    }
    CHECK(sn_abi_version() == SN_ABI_VERSION);
    last_error_semantics();
    navigator((const char *)rig, rig_len, stream, stream_len);
    localizer((const char *)rig, rig_len, map, map_len, stream, stream_len);
    free(rig);
    free(map);
    free(stream);
    if (failures > 0) {
        fprintf(stderr, "api_test: %d checks failed\n", failures);
        return 1;
    }
    printf("api_test: every check held\n");
    return 0;
}
