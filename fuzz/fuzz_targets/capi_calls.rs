//! The C interface driven by arbitrary calls (issue 38, item 2): the input is read as a
//! sequence of calls, one selector byte and the bytes of its arguments each: every function
//! of stereonav.h with NULL or live handles and pointers, arbitrary numbers (NaN, infinities,
//! times in any order), arbitrary rig texts, map bytes and board bytes. Each call must answer
//! SN_OK or a negative code other than SN_E_INTERNAL (a panic caught at the boundary), with a
//! one-line message, and never crash. CI runs the same property through proptest on stable
//! (crates/capi/tests/random_calls.rs).
#![no_main]

use libfuzzer_sys::fuzz_target;
use stereonav::*;

/// The rig every navigator and localiser starts from when the input asks for a good one.
const RIG: &str = include_str!("../../fixtures/logs/paper-experiment.rig.toml");

struct Input<'a>(&'a [u8]);

impl Input<'_> {
    fn byte(&mut self) -> Option<u8> {
        let (&b, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(b)
    }
    fn u64(&mut self) -> Option<u64> {
        let (head, rest) = self.0.split_at_checked(8)?;
        self.0 = rest;
        Some(u64::from_le_bytes(head.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        self.u64().map(f64::from_bits)
    }
    fn bytes(&mut self) -> Option<&[u8]> {
        let n = usize::from(self.byte()?) * 4;
        let n = n.min(self.0.len());
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Some(head)
    }
}

fn judged(code: i32) {
    assert!(code <= 0 && code != SN_E_INTERNAL, "code {code}");
    if code < 0 {
        // SAFETY: NULL with length 0 is allowed.
        assert!(unsafe { sn_last_error(std::ptr::null_mut(), 0) } > 0);
    }
}

fuzz_target!(|data: &[u8]| {
    let mut input = Input(data);
    let mut nav: *mut sn_navigator = std::ptr::null_mut();
    let mut loc: *mut sn_localizer = std::ptr::null_mut();
    while let Some(selector) = input.byte() {
        // SAFETY (every call): handles are NULL or live, freed once; pointers point to the
        // lengths given; outputs are writable.
        unsafe {
            match selector % 12 {
                0 => {
                    sn_navigator_free(nav);
                    nav = std::ptr::null_mut();
                    let text: Vec<u8> = match input.bytes() {
                        Some(b) if !b.is_empty() => b.to_vec(),
                        _ => RIG.as_bytes().to_vec(),
                    };
                    judged(sn_navigator_new(text.as_ptr().cast(), text.len(), &raw mut nav));
                }
                1 => {
                    sn_localizer_free(loc);
                    loc = std::ptr::null_mut();
                    let map = input.bytes().unwrap_or_default().to_vec();
                    judged(sn_localizer_new(RIG.as_ptr().cast(), RIG.len(), map.as_ptr(), map.len(), &raw mut loc));
                }
                2 => {
                    let (Some(t), Some(a), Some(b), Some(c)) = (input.u64(), input.f64(), input.f64(), input.f64()) else { break };
                    judged(sn_navigator_push_odometry(nav, t, a, b, c));
                    judged(sn_localizer_push_odometry(loc, t, a, b, c));
                }
                3 => {
                    let bytes = input.bytes().unwrap_or_default().to_vec();
                    let mut done = 0usize;
                    judged(sn_navigator_push_stream(nav, bytes.as_ptr(), bytes.len(), &raw mut done));
                    judged(sn_localizer_push_stream(loc, bytes.as_ptr(), bytes.len(), std::ptr::null_mut()));
                }
                4 => {
                    let Some(t) = input.u64() else { break };
                    let raw = input.bytes().unwrap_or_default();
                    let features: Vec<sn_feature> = raw
                        .chunks_exact(8)
                        .map(|c| sn_feature {
                            x_q4: u16::from_le_bytes([c[0], c[1]]),
                            y_q4: u16::from_le_bytes([c[2], c[3]]),
                            r: i32::from_le_bytes([c[4], c[5], c[6], c[7]]),
                        })
                        .collect();
                    let half = features.len() / 2;
                    judged(sn_navigator_push_frame(nav, t, features.as_ptr(), half, features[half..].as_ptr(), features.len() - half));
                }
                5 => judged(sn_navigator_finish(nav)),
                6 => {
                    let mut pose = sn_pose::default();
                    judged(sn_navigator_pose(nav, &raw mut pose));
                    judged(sn_localizer_pose(loc, &raw mut pose));
                }
                7 => {
                    let cap = usize::from(input.byte().unwrap_or(0) % 16);
                    let mut out = vec![sn_landmark::default(); cap];
                    let mut count = 0usize;
                    judged(sn_navigator_landmarks(nav, out.as_mut_ptr(), cap, &raw mut count));
                }
                8 => {
                    let mut name = input.bytes().unwrap_or_default().to_vec();
                    name.retain(|&b| b != 0);
                    name.push(0);
                    let (mut v, mut s) = (0.0, 0.0);
                    judged(sn_navigator_parameter(nav, name.as_ptr().cast(), &raw mut v, &raw mut s));
                }
                9 => {
                    let len = usize::from(input.byte().unwrap_or(0));
                    let mut buf = vec![0 as std::ffi::c_char; len];
                    sn_last_error(buf.as_mut_ptr(), len);
                }
                10 => {
                    judged(sn_navigator_push_odometry(std::ptr::null_mut(), 0, 0.0, 0.0, 0.0));
                    judged(sn_navigator_pose(nav, std::ptr::null_mut()));
                }
                _ => {
                    sn_navigator_free(nav);
                    sn_localizer_free(loc);
                    nav = std::ptr::null_mut();
                    loc = std::ptr::null_mut();
                }
            }
        }
    }
    // SAFETY: live or NULL, freed once.
    unsafe {
        sn_navigator_free(nav);
        sn_localizer_free(loc);
    }
});
