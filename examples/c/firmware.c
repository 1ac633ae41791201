/*
 * firmware.c: a vehicle controller's main loop on stereonav's C interface (docs/c-api.md).
 *
 * On a vehicle, two interrupt handlers feed the stack: the UART driver hands over the camera
 * board's bytes as they arrive (any chunking: a packet is split across calls as the FIFO
 * fills), and the wheel encoders' callback gives the robot-frame velocities at 100 Hz. The
 * main loop reads the pose after every frame. Here a recording stands in for both: a file of
 * records in arrival order (written by crates/capi/tests/c_programs.rs from a vehicle log):
 *
 *   u8 kind = 0, u64 t_us, f64 vx, f64 vy, f64 vtheta     the wheel encoders
 *   u8 kind = 1, u64 t_us, u32 n, n bytes                  the board's bytes of one frame
 *
 * (little-endian), and the UART driver cuts each frame's bytes into chunks of 1 to 64 bytes.
 *
 *   firmware RIG.toml INPUTS.bin
 *
 * prints how many frames it saw and the final pose, then one line per landmark
 * ("landmark id x y z sx sy sz observations") and per parameter ("parameter name value
 * sigma"), so that a test can compare it with `stereonav replay`.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "stereonav.h"

static sn_navigator *navigator;
static size_t frames_seen;
static unsigned long stream_warnings;

/* The last failure's message, for the log. */
static void report(const char *what, int rc)
{
    char message[512];
    sn_last_error(message, sizeof message);
    fprintf(stderr, "firmware: %s returned %d: %s\n", what, rc, message);
}

/* The wheel encoders' callback: velocities in the robot frame (m/s, m/s, rad/s). */
static void on_wheel_encoders(uint64_t t_us, double vx, double vy, double vtheta)
{
    int rc = sn_navigator_push_odometry(navigator, t_us, vx, vy, vtheta);
    if (rc != SN_OK) {
        report("sn_navigator_push_odometry", rc);
    }
}

/* The UART driver's receive callback: whatever bytes arrived. */
static void on_uart_bytes(const uint8_t *bytes, size_t len)
{
    size_t frames = 0;
    int rc = sn_navigator_push_stream(navigator, bytes, len, &frames);
    if (rc == SN_E_STREAM) {
        stream_warnings++; /* corrupt packets skipped: the link is noisy, carry on */
    } else if (rc != SN_OK) {
        report("sn_navigator_push_stream", rc);
    }
    frames_seen += frames;
    if (frames > 0) {
        sn_pose pose;
        if (sn_navigator_pose(navigator, &pose) == SN_OK) {
            /* Here the controller would steer by pose.x, pose.y, pose.theta. */
            (void)pose;
        }
    }
}

static int read_exact(FILE *f, void *out, size_t n)
{
    return fread(out, 1, n, f) == n;
}

static char *read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    char *text;
    long n;
    if (f == NULL || fseek(f, 0, SEEK_END) != 0 || (n = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
        if (f != NULL) {
            fclose(f);
        }
        return NULL;
    }
    text = malloc((size_t)n + 1);
    if (text == NULL || !read_exact(f, text, (size_t)n)) {
        free(text);
        fclose(f);
        return NULL;
    }
    fclose(f);
    text[n] = '\0';
    *len = (size_t)n;
    return text;
}

int main(int argc, char **argv)
{
    static const char *const parameters[] = {
        "f", "cx", "cy", "baseline", "mount_x", "mount_y", "mount_z", "mount_roll",
        "mount_pitch", "mount_yaw", "odom_scale", "odom_yaw_scale", "odom_yaw_bias", "time_offset",
    };
    size_t rig_len = 0, count = 0, i;
    char *rig;
    FILE *inputs;
    uint8_t *frame = NULL;
    uint32_t seed = 12345u; /* the UART's chunk sizes: a fixed pseudo-random sequence */
    sn_landmark *landmarks;
    sn_pose pose;
    int rc;

    if (argc != 3) {
        fprintf(stderr, "usage: firmware RIG.toml INPUTS.bin\n");
        return 2;
    }
    rig = read_file(argv[1], &rig_len);
    if (rig == NULL) {
        fprintf(stderr, "firmware: cannot read %s\n", argv[1]);
        return 1;
    }
    rc = sn_navigator_new(rig, rig_len, &navigator);
    free(rig);
    if (rc != SN_OK) {
        report("sn_navigator_new", rc);
        return 1;
    }
    inputs = fopen(argv[2], "rb");
    if (inputs == NULL) {
        fprintf(stderr, "firmware: cannot read %s\n", argv[2]);
        sn_navigator_free(navigator);
        return 1;
    }
    for (;;) {
        uint8_t kind;
        uint64_t t_us;
        if (!read_exact(inputs, &kind, 1)) {
            break;
        }
        if (!read_exact(inputs, &t_us, sizeof t_us)) {
            break;
        }
        if (kind == 0) {
            double v[3];
            if (!read_exact(inputs, v, sizeof v)) {
                break;
            }
            on_wheel_encoders(t_us, v[0], v[1], v[2]);
        } else {
            uint32_t n;
            size_t done = 0;
            uint8_t *grown;
            if (!read_exact(inputs, &n, sizeof n)) {
                break;
            }
            grown = realloc(frame, n > 0 ? n : 1);
            if (grown == NULL) {
                break;
            }
            frame = grown;
            if (!read_exact(inputs, frame, n)) {
                break;
            }
            while (done < n) {
                size_t chunk;
                seed = seed * 1103515245u + 12345u;
                chunk = 1 + (seed >> 16) % 64;
                if (chunk > n - done) {
                    chunk = n - done;
                }
                on_uart_bytes(frame + done, chunk);
                done += chunk;
            }
        }
    }
    free(frame);
    fclose(inputs);

    rc = sn_navigator_finish(navigator);
    if (rc != SN_OK) {
        report("sn_navigator_finish", rc);
    }
    if (sn_navigator_pose(navigator, &pose) == SN_OK) {
        printf("frames %lu\n", (unsigned long)frames_seen);
        printf("stream_warnings %lu\n", stream_warnings);
        printf("pose %.9f %.9f %.9f phase %d\n", pose.x, pose.y, pose.theta, (int)pose.phase);
    }
    rc = sn_navigator_landmarks(navigator, NULL, 0, &count);
    if (rc != SN_OK) {
        report("sn_navigator_landmarks", rc);
    }
    landmarks = malloc((count > 0 ? count : 1) * sizeof *landmarks);
    if (landmarks != NULL && sn_navigator_landmarks(navigator, landmarks, count, &count) == SN_OK) {
        for (i = 0; i < count; i++) {
            const sn_landmark *l = &landmarks[i];
            printf("landmark %lu %.9f %.9f %.9f %.9g %.9g %.9g %lu\n", (unsigned long)l->id, l->x,
                   l->y, l->z, l->sigma[0], l->sigma[1], l->sigma[2], (unsigned long)l->observations);
        }
    }
    free(landmarks);
    for (i = 0; i < sizeof parameters / sizeof parameters[0]; i++) {
        double value, sigma;
        if (sn_navigator_parameter(navigator, parameters[i], &value, &sigma) == SN_OK) {
            printf("parameter %s %.12g %.12g\n", parameters[i], value, sigma);
        }
    }
    sn_navigator_free(navigator);
    return 0;
}
