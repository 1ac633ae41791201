//! The interface driven by random calls (issue 38, item 2): sequences of every function with
//! random arguments (NULL or live handles and pointers, NaN and infinities, times in and out
//! of order, junk and real board bytes, cut and flipped rig texts and maps), as a fuzzer
//! would. Each call must return `SN_OK` or a negative `SN_E_*` code with a one-line message,
//! and never panic or abort (a panic caught at the boundary is `SN_E_INTERNAL`, which fails
//! here too).
#![allow(clippy::unwrap_used, clippy::expect_used, unsafe_code)]

mod support;

use std::ffi::{CString, c_char};
use std::sync::OnceLock;

use proptest::prelude::*;
use stereonav::*;

/// The paper experiment's rig text, its first board bytes and the map replay saves of it.
struct Data {
    rig: Vec<u8>,
    stream: Vec<u8>,
    map: Vec<u8>,
}

fn data() -> &'static Data {
    static DATA: OnceLock<Data> = OnceLock::new();
    DATA.get_or_init(|| {
        let paper = support::paper();
        let mut stream = paper.stream;
        stream.truncate(40_000);
        Data {
            rig: std::fs::read(&paper.rig_path).unwrap(),
            stream,
            map: paper.map,
        }
    })
}

/// One call of the interface.
#[derive(Debug, Clone)]
enum Call {
    NewNavigator {
        cut: usize,
        flip: Option<usize>,
    },
    NewLocalizer {
        cut: usize,
        flip: Option<usize>,
    },
    Odometry {
        t_us: u64,
        v: [f64; 3],
        null: bool,
    },
    Stream {
        from: usize,
        len: usize,
        junk: Option<Vec<u8>>,
        null: bool,
    },
    Frame {
        t_us: u64,
        n_left: usize,
        n_right: usize,
        null: bool,
    },
    Finish,
    Pose {
        null_out: bool,
    },
    Landmarks {
        cap: usize,
        null_out: bool,
    },
    Parameter {
        name: String,
    },
    LastError {
        len: usize,
    },
    Free,
}

fn number() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => -3.0..3.0_f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(-1e300),
    ]
}

fn call() -> impl Strategy<Value = Call> {
    prop_oneof![
        (0..2000_usize, proptest::option::of(0..2000_usize))
            .prop_map(|(cut, flip)| Call::NewNavigator { cut, flip }),
        (0..2000_usize, proptest::option::of(0..4000_usize))
            .prop_map(|(cut, flip)| Call::NewLocalizer { cut, flip }),
        (
            0..60_000_000_u64,
            [number(), number(), number()],
            any::<bool>()
        )
            .prop_map(|(t_us, v, null)| Call::Odometry { t_us, v, null }),
        (
            0..40_000_usize,
            0..3000_usize,
            proptest::option::of(proptest::collection::vec(any::<u8>(), 0..400)),
            proptest::bool::weighted(0.05)
        )
            .prop_map(|(from, len, junk, null)| Call::Stream {
                from,
                len,
                junk,
                null
            }),
        (
            0..60_000_000_u64,
            0..40_usize,
            0..40_usize,
            proptest::bool::weighted(0.1)
        )
            .prop_map(|(t_us, n_left, n_right, null)| Call::Frame {
                t_us,
                n_left,
                n_right,
                null
            }),
        Just(Call::Finish),
        any::<bool>().prop_map(|null_out| Call::Pose { null_out }),
        (0..8_usize, proptest::bool::weighted(0.2))
            .prop_map(|(cap, null_out)| Call::Landmarks { cap, null_out }),
        prop_oneof![
            Just("baseline".to_string()),
            Just("odom_scale".to_string()),
            Just("time_offset".to_string()),
            "[a-z_]{0,12}",
        ]
        .prop_map(|name| Call::Parameter { name }),
        (0..80_usize).prop_map(|len| Call::LastError { len }),
        Just(Call::Free),
    ]
}

/// A code is `SN_OK` or a negative code other than the internal error, with its message.
fn judged(what: &str, code: i32) {
    assert!(code <= 0, "{what}: {code}");
    assert_ne!(
        code, SN_E_INTERNAL,
        "{what}: a panic was caught at the boundary"
    );
    if code < 0 {
        // SAFETY: NULL with length 0 is allowed.
        let n = unsafe { sn_last_error(std::ptr::null_mut(), 0) };
        let mut buf = vec![0 as c_char; n + 1];
        // SAFETY: `buf` has `n + 1` writable bytes.
        unsafe { sn_last_error(buf.as_mut_ptr(), buf.len()) };
        let text: Vec<u8> = buf.iter().take(n).map(|&c| c as u8).collect();
        assert!(n > 0 && !text.contains(&b'\n'), "{what}: message {text:?}");
    }
}

fn run(calls: &[Call]) {
    let d = data();
    let mut nav: *mut sn_navigator = std::ptr::null_mut();
    let mut loc: *mut sn_localizer = std::ptr::null_mut();
    for c in calls {
        match c {
            Call::NewNavigator { cut, flip } => {
                let mut rig = d.rig.clone();
                rig.truncate(rig.len().saturating_sub(*cut % (rig.len() / 4 + 1)));
                let n = rig.len().max(1);
                if let Some(i) = flip
                    && let Some(b) = rig.get_mut(*i % n)
                {
                    *b ^= 0x5a;
                }
                // SAFETY: a live handle or NULL.
                unsafe { sn_navigator_free(nav) };
                nav = std::ptr::null_mut();
                // SAFETY: `rig` has its length readable; `nav` is writable.
                let code =
                    unsafe { sn_navigator_new(rig.as_ptr().cast(), rig.len(), &raw mut nav) };
                judged("sn_navigator_new", code);
                assert_eq!(code == SN_OK, !nav.is_null());
            }
            Call::NewLocalizer { cut, flip } => {
                let mut map = d.map.clone();
                map.truncate(map.len().saturating_sub(*cut % 3));
                let n = map.len().max(1);
                if let Some(i) = flip
                    && let Some(b) = map.get_mut(*i % n)
                {
                    *b ^= 0x01;
                }
                // SAFETY: a live handle or NULL.
                unsafe { sn_localizer_free(loc) };
                loc = std::ptr::null_mut();
                // SAFETY: the slices' lengths are readable; `loc` is writable.
                let code = unsafe {
                    sn_localizer_new(
                        d.rig.as_ptr().cast(),
                        d.rig.len(),
                        map.as_ptr(),
                        map.len(),
                        &raw mut loc,
                    )
                };
                judged("sn_localizer_new", code);
            }
            Call::Odometry { t_us, v, null } => {
                let (n, l) = if *null {
                    (std::ptr::null_mut(), std::ptr::null_mut())
                } else {
                    (nav, loc)
                };
                // SAFETY: live handles or NULL.
                unsafe {
                    judged(
                        "odometry",
                        sn_navigator_push_odometry(n, *t_us, v[0], v[1], v[2]),
                    );
                    judged(
                        "odometry",
                        sn_localizer_push_odometry(l, *t_us, v[0], v[1], v[2]),
                    );
                }
            }
            Call::Stream {
                from,
                len,
                junk,
                null,
            } => {
                let bytes: Vec<u8> = match junk {
                    Some(j) => j.clone(),
                    None => {
                        let a = (*from).min(d.stream.len());
                        let b = (a + len).min(d.stream.len());
                        d.stream[a..b].to_vec()
                    }
                };
                let ptr = if *null {
                    std::ptr::null()
                } else {
                    bytes.as_ptr()
                };
                let mut done = 0_usize;
                // SAFETY: `bytes.len()` readable bytes (or NULL, refused); live handles or NULL.
                unsafe {
                    judged(
                        "stream",
                        sn_navigator_push_stream(nav, ptr, bytes.len(), &raw mut done),
                    );
                    judged(
                        "stream",
                        sn_localizer_push_stream(loc, ptr, bytes.len(), std::ptr::null_mut()),
                    );
                }
            }
            Call::Frame {
                t_us,
                n_left,
                n_right,
                null,
            } => {
                let f = |k: usize| sn_feature {
                    x_q4: u16::try_from((k * 977) % 12_000).unwrap(),
                    y_q4: u16::try_from((k * 613) % 7_600).unwrap(),
                    r: i32::try_from(k).unwrap() * 1000,
                };
                let left: Vec<sn_feature> = (0..*n_left).map(f).collect();
                let right: Vec<sn_feature> = (0..*n_right).map(|k| f(k + 3)).collect();
                let lp = if *null {
                    std::ptr::null()
                } else {
                    left.as_ptr()
                };
                // SAFETY: the counts' features are readable (or NULL, refused).
                let code = unsafe {
                    sn_navigator_push_frame(nav, *t_us, lp, left.len(), right.as_ptr(), right.len())
                };
                judged("sn_navigator_push_frame", code);
            }
            Call::Finish => {
                // SAFETY: a live handle or NULL.
                judged("sn_navigator_finish", unsafe { sn_navigator_finish(nav) });
            }
            Call::Pose { null_out } => {
                let mut pose = sn_pose::default();
                let out: *mut sn_pose = if *null_out {
                    std::ptr::null_mut()
                } else {
                    &raw mut pose
                };
                // SAFETY: live handles or NULL; `out` writable or NULL.
                unsafe {
                    judged("sn_navigator_pose", sn_navigator_pose(nav, out));
                    judged("sn_localizer_pose", sn_localizer_pose(loc, out));
                }
            }
            Call::Landmarks { cap, null_out } => {
                let mut buf = vec![sn_landmark::default(); *cap];
                let out = if *null_out {
                    std::ptr::null_mut()
                } else {
                    buf.as_mut_ptr()
                };
                let mut count = 0_usize;
                // SAFETY: `cap` writable landmarks (or NULL, refused when cap > 0).
                let code = unsafe { sn_navigator_landmarks(nav, out, *cap, &raw mut count) };
                judged("sn_navigator_landmarks", code);
            }
            Call::Parameter { name } => {
                let name = CString::new(name.as_str()).unwrap();
                let (mut v, mut s) = (0.0, 0.0);
                // SAFETY: a NUL-terminated name; writable outputs.
                let code =
                    unsafe { sn_navigator_parameter(nav, name.as_ptr(), &raw mut v, &raw mut s) };
                judged("sn_navigator_parameter", code);
            }
            Call::LastError { len } => {
                let mut buf = vec![1 as c_char; *len];
                let ptr = if *len == 0 {
                    std::ptr::null_mut()
                } else {
                    buf.as_mut_ptr()
                };
                // SAFETY: `len` writable bytes.
                let n = unsafe { sn_last_error(ptr, *len) };
                if *len > 0 {
                    let written = n.min(len - 1);
                    assert_eq!(buf[written], 0, "NUL after the copied message");
                }
            }
            Call::Free => {
                // SAFETY: live handles or NULL, freed once.
                unsafe {
                    sn_navigator_free(nav);
                    sn_localizer_free(loc);
                }
                nav = std::ptr::null_mut();
                loc = std::ptr::null_mut();
            }
        }
    }
    // SAFETY: live handles or NULL, freed once.
    unsafe {
        sn_navigator_free(nav);
        sn_localizer_free(loc);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn random_calls_are_answered_with_codes_never_a_crash(
        calls in proptest::collection::vec(call(), 1..60)
    ) {
        // A navigator and a localiser to start with, most of the time.
        let mut all = vec![Call::NewNavigator { cut: 0, flip: None }, Call::NewLocalizer { cut: 0, flip: None }];
        all.extend(calls);
        run(&all);
    }
}
