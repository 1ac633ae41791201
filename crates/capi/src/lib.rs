//! The C interface of stereonav (vehicle-interfaces.md section 7): vehicle firmware in C links
//! the navigator (the whole method: phase 1, the switch, phase 2) and the localiser (a saved
//! map) through `include/stereonav.h`, which cbindgen generates from this file (the test
//! `tests/header.rs` fails when the committed header differs; `SN_BLESS=1` rewrites it).
//!
//! Every function is total: it returns `SN_OK` (0) or a negative `SN_E_*` code, and on an
//! error the one-line message that [`sn_last_error`] gives back. NULL handles and pointers,
//! non-finite numbers, times out of order, rig text that is not a rig, map bytes that are not a
//! map and junk in the board's byte stream are all answered with a code; a Rust panic (a bug)
//! is caught at the boundary and answered with `SN_E_INTERNAL`, never unwound into C. No
//! function reads past a size it was given; pointers given with a size must point to that many
//! readable elements (C cannot tell us otherwise).
//!
//! Memory: `sn_navigator_new` and `sn_localizer_new` allocate a handle that the caller frees
//! with `sn_navigator_free` / `sn_localizer_free` (NULL is accepted); everything else writes
//! into memory the caller owns and never keeps a pointer it was given.
//!
//! docs/c-api.md says how to build and link it and shows a firmware main loop
//! (`examples/c/firmware.c`).
// The C boundary is `unsafe` by nature: raw pointers from C, `#[no_mangle]` symbols. Each
// `unsafe` block says what it relies on.
//!
//! Without `std` (`--no-default-features --features firmware`, for firmware without an
//! operating system) the navigator's functions are the same, the memory comes from the
//! firmware's `sn_firmware_alloc` / `sn_firmware_free`, a panic (a bug) ends in its
//! `sn_firmware_panic`, the last error is one for the whole program, and the localiser's
//! functions answer `SN_E_REFUSED` (reading a map needs `std`).
#![allow(unsafe_code, non_camel_case_types)]
#![cfg_attr(not(feature = "std"), no_std)]

extern crate alloc;

use alloc::boxed::Box;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::ffi::{c_char, c_int};

use fpga_link::{Decoder, Event};
use nav::sequencer::{Sequenced, Sequencer};
use nav::{NavSettings, Navigator, Phase};
use rig_model::odometry::OdomSample;
use rig_model::{Param, Rig};
use track::Pixel;

/// The ABI's version: changes only when a fixed signature changes.
pub const SN_ABI_VERSION: u32 = 1;

/// Success.
pub const SN_OK: c_int = 0;
/// A handle or a pointer that must not be NULL was NULL.
pub const SN_E_NULL: c_int = -1;
/// An argument out of its domain: a non-finite number, an unknown parameter name, a size
/// that does not fit.
pub const SN_E_ARGUMENT: c_int = -2;
/// A time older than the previous one (odometry or frame).
pub const SN_E_ORDER: c_int = -3;
/// The rig text is not a rig file (TOML, section 3, or its JSON form, section 4).
pub const SN_E_RIG: c_int = -4;
/// The map bytes are not a map the localiser can use (another format, damaged, empty).
pub const SN_E_MAP: c_int = -5;
/// The board's byte stream held corrupt packets or junk: skipped and counted; the good
/// frames around them were processed (`*frames_done` says how many).
pub const SN_E_STREAM: c_int = -6;
/// The estimator refused the data for another reason (the message says which).
pub const SN_E_REFUSED: c_int = -7;
/// A bug in the library, caught at the boundary (please report the message).
pub const SN_E_INTERNAL: c_int = -8;

/// One feature of the board (board-icd.md section 3): the corner's position in 1/16 pixel
/// and its Harris response.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct sn_feature {
    /// Column, 1/16 pixel.
    pub x_q4: u16,
    /// Row, 1/16 pixel.
    pub y_q4: u16,
    /// Harris response.
    pub r: i32,
}

/// A planar pose with its covariance.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct sn_pose {
    /// The time of the frame it is at, microseconds (0 before the first frame).
    pub t_us: u64,
    /// Position, metres (the navigator's world frame: its first frame's; the map's frame for
    /// the localiser).
    pub x: f64,
    /// See `x`.
    pub y: f64,
    /// Heading, radians.
    pub theta: f64,
    /// Covariance, row-major over `(x, y, theta)`.
    pub cov: [f64; 9],
    /// 0 while calibrating (phase 1), 1 while navigating (phase 2); the localiser: 1.
    pub phase: i32,
    /// The localiser: 1 while it stands behind the pose, 0 while lost. The navigator: 1.
    pub localized: i32,
}

/// A mapped landmark.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct sn_landmark {
    /// Its id (as `SUMMARY.json`'s).
    pub id: u32,
    /// Position in the world frame, metres.
    pub x: f64,
    /// See `x`.
    pub y: f64,
    /// See `x`.
    pub z: f64,
    /// Standard deviations of x, y and z, metres.
    pub sigma: [f64; 3],
    /// Observations that updated it.
    pub observations: u32,
}

/// A frame's left and right features, in pixels.
type Frame = (Vec<Pixel>, Vec<Pixel>);

/// What both handles share: the board's stream decoder and the window that puts frames and
/// odometry in data-time order, each frame after the odometry up to its look-ahead, as
/// `stereonav replay` does (`nav::sequencer`), so that a log fed through the C interface gives
/// the replay's map.
#[derive(Debug, Default)]
struct Inputs {
    decoder: Decoder,
    window: Sequencer<Frame>,
    last_odometry_t: Option<u64>,
    last_frame_t: Option<u64>,
}

impl Inputs {
    /// An odometry sample into the window, checked.
    fn odometry(&mut self, t_us: u64, vx: f64, vy: f64, vtheta: f64) -> Result<(), Failure> {
        let sample = odometry(t_us, vx, vy, vtheta)?;
        if let Some(last) = self.last_odometry_t
            && t_us < last
        {
            return Err(Failure::new(
                SN_E_ORDER,
                format!("odometry at t = {t_us} us is older than the previous sample ({last} us)"),
            ));
        }
        self.last_odometry_t = Some(t_us);
        self.window.push_odometry(sample);
        Ok(())
    }

    /// A frame into the window, checked.
    fn frame(&mut self, t_us: u64, frame: Frame) -> Result<(), Failure> {
        if let Some(last) = self.last_frame_t
            && t_us < last
        {
            return Err(Failure::new(
                SN_E_ORDER,
                format!("frame at t = {t_us} us is older than the previous frame ({last} us)"),
            ));
        }
        self.last_frame_t = Some(t_us);
        self.window.push_frame(t_us, frame);
        Ok(())
    }

    /// `bytes` of the board's stream: every complete good frame into the window, counted in
    /// `done`. Corrupt packets and junk are skipped, and said after every frame was taken, as
    /// is a frame out of order (the first such error).
    fn stream(&mut self, bytes: &[u8], done: &mut usize) -> Result<(), Failure> {
        let before = self.decoder.stats();
        let mut rest = bytes;
        let mut refused: Option<Failure> = None;
        loop {
            let (used, event) = self.decoder.decode(rest);
            rest = rest.get(used..).unwrap_or_default();
            let (t_us, frame) = match event {
                Some(Event::Frame(f)) => (f.t_us(), pixels(&f)),
                Some(Event::Corrupt(_)) => continue,
                None => break,
            };
            match self.frame(t_us, frame) {
                Ok(()) => *done += 1,
                Err(e) => {
                    refused.get_or_insert(e);
                }
            }
        }
        if let Some(e) = refused {
            return Err(e);
        }
        let after = self.decoder.stats();
        let corrupt = after.corrupt - before.corrupt;
        let skipped = after.bytes_skipped - before.bytes_skipped;
        if corrupt > 0 || skipped > 0 {
            return Err(Failure::new(
                SN_E_STREAM,
                format!(
                    "{corrupt} corrupt packets and {skipped} bytes of junk skipped ({done} frames taken)"
                ),
            ));
        }
        Ok(())
    }

    /// The end of the data: a packet still incomplete decoded as far as it goes, and the
    /// window let out whole.
    fn end(&mut self) -> Result<(), Failure> {
        let mut frames = Vec::new();
        while let Some(event) = self.decoder.decode_end() {
            if let Event::Frame(f) = event {
                frames.push((f.t_us(), pixels(&f)));
            }
        }
        let mut refused = None;
        for (t, frame) in frames {
            if let Err(e) = self.frame(t, frame) {
                refused.get_or_insert(e);
            }
        }
        self.window.end();
        refused.map_or(Ok(()), Err)
    }
}

/// A decoded frame's features in pixels.
fn pixels(f: &fpga_link::Frame<'_>) -> Frame {
    let px = |x: fpga_link::Feature| Pixel::from_q4(x.x_q4, x.y_q4);
    (f.left().map(px).collect(), f.right().map(px).collect())
}

/// The navigator: the whole method (phase 1 self-calibration, the switch, phase 2 EKF SLAM)
/// behind an opaque handle.
#[derive(Debug)]
pub struct sn_navigator {
    nav: Navigator,
    inputs: Inputs,
}

impl sn_navigator {
    /// Runs what the window lets out through the navigator; the first error it gave.
    fn run(&mut self) -> Result<(), Failure> {
        let mut first = None;
        while let Some(input) = self.inputs.window.pop() {
            let result = match input {
                Sequenced::Odometry(s) => self.nav.push_odometry(s),
                Sequenced::Frame(t, (l, r)) => self.nav.push_frame(t, &l, &r).map(|_| ()),
            };
            if let Err(e) = result {
                first.get_or_insert(Failure::new(nav_code(&e), e.to_string()));
            }
        }
        first.map_or(Ok(()), Err)
    }
}

/// The localiser on a saved map behind an opaque handle.
#[derive(Debug)]
pub struct sn_localizer {
    #[cfg_attr(not(feature = "std"), allow(dead_code))]
    inner: LocalizerInner,
}

/// The localiser's state (with `std`).
#[cfg(feature = "std")]
#[derive(Debug)]
struct LocalizerInner {
    loc: localize::Localizer,
    inputs: Inputs,
    last: Option<localize::FrameResult>,
}

/// Without `std` there is no localiser: no handle is ever made.
#[cfg(not(feature = "std"))]
#[derive(Debug)]
struct LocalizerInner {
    _never: core::convert::Infallible,
}

/// The localiser's refusal without `std`.
#[cfg(not(feature = "std"))]
fn no_localizer() -> Failure {
    Failure::new(
        SN_E_REFUSED,
        "this library was built without std: the localiser (which reads map files) is not in it",
    )
}

#[cfg(feature = "std")]
impl LocalizerInner {
    /// Runs what the window lets out through the localiser; the first error it gave.
    fn run(&mut self) -> Result<(), Failure> {
        let mut first = None;
        while let Some(input) = self.inputs.window.pop() {
            let result = match input {
                Sequenced::Odometry(s) => self.loc.push_odometry(s),
                Sequenced::Frame(t, (l, r)) => self.loc.push_frame(t, &l, &r).map(|r| {
                    self.last = Some(r);
                }),
            };
            if let Err(e) = result {
                first.get_or_insert(Failure::new(loc_code(&e), e.to_string()));
            }
        }
        first.map_or(Ok(()), Err)
    }
}

#[cfg(feature = "std")]
std::thread_local! {
    /// The last failed call's message, per thread.
    static LAST_ERROR: core::cell::RefCell<String> = const { core::cell::RefCell::new(String::new()) };
}

/// Without `std`: the last failed call's message, one for the program (firmware runs the
/// stack from one task), behind a flag that keeps two writers apart.
#[cfg(not(feature = "std"))]
struct LastError {
    busy: core::sync::atomic::AtomicBool,
    text: core::cell::UnsafeCell<String>,
}

// SAFETY: `text` is only reached inside `with`, which holds `busy` for the access.
#[cfg(not(feature = "std"))]
unsafe impl Sync for LastError {}

#[cfg(not(feature = "std"))]
impl LastError {
    /// Runs `f` on the message, waiting while another caller holds it.
    fn with<R>(&self, f: impl FnOnce(&mut String) -> R) -> R {
        use core::sync::atomic::Ordering;
        while self
            .busy
            .compare_exchange_weak(false, true, Ordering::Acquire, Ordering::Relaxed)
            .is_err()
        {
            core::hint::spin_loop();
        }
        // SAFETY: `busy` is held: no other reference to `text` exists.
        let r = f(unsafe { &mut *self.text.get() });
        self.busy.store(false, Ordering::Release);
        r
    }
}

#[cfg(not(feature = "std"))]
static LAST_ERROR: LastError = LastError {
    busy: core::sync::atomic::AtomicBool::new(false),
    text: core::cell::UnsafeCell::new(String::new()),
};

/// Runs `f` on the last error's text.
fn last_error<R>(f: impl FnOnce(&mut String) -> R) -> R {
    #[cfg(feature = "std")]
    {
        LAST_ERROR.with(|e| f(&mut e.borrow_mut()))
    }
    #[cfg(not(feature = "std"))]
    {
        LAST_ERROR.with(f)
    }
}

/// An error: its code and one-line message.
struct Failure(c_int, String);

impl Failure {
    fn new(code: c_int, message: impl Into<String>) -> Self {
        Self(code, message.into())
    }
}

/// Runs `body` at the boundary: its error, or a panic, becomes a code and the last message.
fn boundary(what: &str, body: impl FnOnce() -> Result<(), Failure>) -> c_int {
    match caught(body) {
        Ok(Ok(())) => SN_OK,
        Ok(Err(Failure(code, message))) => {
            set_error(format!("{what}: {message}"));
            code
        }
        Err(text) => {
            set_error(format!("{what}: internal error (a bug): {text}"));
            SN_E_INTERNAL
        }
    }
}

/// `body`'s result, or a panic's message (with `std`; without it a panic ends in the
/// firmware's `sn_firmware_panic`).
fn caught<T>(body: impl FnOnce() -> T) -> Result<T, String> {
    #[cfg(feature = "std")]
    {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(body)).map_err(|panic| {
            panic
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_string())
        })
    }
    #[cfg(not(feature = "std"))]
    {
        Ok(body())
    }
}

fn set_error(message: String) {
    // One line, whatever the inner errors held.
    let line = message.replace(['\n', '\r'], " ");
    last_error(|e| *e = line);
}

/// `ptr` as a reference, or `SN_E_NULL` naming `what`.
///
/// # Safety
/// `ptr` is NULL or points to a valid `T` for the call.
unsafe fn non_null<'a, T>(ptr: *const T, what: &str) -> Result<&'a T, Failure> {
    // SAFETY: the caller's contract (a valid pointer or NULL).
    unsafe { ptr.as_ref() }.ok_or_else(|| Failure::new(SN_E_NULL, format!("{what} is NULL")))
}

/// `ptr` as a mutable reference, or `SN_E_NULL` naming `what`.
///
/// # Safety
/// `ptr` is NULL or points to a valid `T` for the call, not aliased.
unsafe fn non_null_mut<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: the caller's contract.
    unsafe { ptr.as_mut() }.ok_or_else(|| Failure::new(SN_E_NULL, format!("{what} is NULL")))
}

/// `len` elements at `ptr` as a slice; an empty slice for `len == 0` (any pointer, NULL too).
///
/// # Safety
/// For `len > 0`, `ptr` is NULL or points to `len` readable `T`.
unsafe fn slice<'a, T>(ptr: *const T, len: usize, what: &str) -> Result<&'a [T], Failure> {
    if len == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(Failure::new(
            SN_E_NULL,
            format!("{what} is NULL with a length of {len}"),
        ));
    }
    if len > isize::MAX as usize / size_of::<T>().max(1) {
        return Err(Failure::new(
            SN_E_ARGUMENT,
            format!("{what}: a length of {len} is too large"),
        ));
    }
    // SAFETY: non-NULL, and the caller's contract gives `len` readable elements.
    Ok(unsafe { core::slice::from_raw_parts(ptr, len) })
}

/// The rig from its file's text: JSON when it starts with `{`, else TOML.
fn parse_rig(text: &[u8]) -> Result<Rig, Failure> {
    let text = core::str::from_utf8(text)
        .map_err(|e| Failure::new(SN_E_RIG, format!("the rig text is not UTF-8 ({e})")))?;
    let parsed = if text.trim_start().starts_with('{') {
        Rig::from_json_str(text, "rig")
    } else {
        Rig::from_toml_str(text, "rig")
    };
    parsed.map_err(|e| Failure::new(SN_E_RIG, e.to_string()))
}

fn odometry(t_us: u64, vx: f64, vy: f64, vtheta: f64) -> Result<OdomSample, Failure> {
    for (name, v) in [("vx", vx), ("vy", vy), ("vtheta", vtheta)] {
        if !v.is_finite() {
            return Err(Failure::new(
                SN_E_ARGUMENT,
                format!("odometry {name} at t = {t_us} us is not finite ({v})"),
            ));
        }
    }
    Ok(OdomSample {
        t_us,
        vx,
        vy,
        vtheta,
    })
}

/// The code of a navigator error.
fn nav_code(e: &nav::Error) -> c_int {
    match e {
        nav::Error::OdometryOutOfOrder { .. } | nav::Error::FrameOutOfOrder { .. } => SN_E_ORDER,
        nav::Error::NonFinite { .. } => SN_E_ARGUMENT,
        _ => SN_E_REFUSED,
    }
}

/// The code of a localiser error.
#[cfg(feature = "std")]
fn loc_code(e: &localize::Error) -> c_int {
    match e {
        localize::Error::OdometryOutOfOrder { .. } | localize::Error::FrameOutOfOrder { .. } => {
            SN_E_ORDER
        }
        localize::Error::NonFinite { .. } => SN_E_ARGUMENT,
        _ => SN_E_REFUSED,
    }
}

/// The ABI's version, [`SN_ABI_VERSION`].
#[unsafe(no_mangle)]
pub extern "C" fn sn_abi_version() -> u32 {
    SN_ABI_VERSION
}

/// Copies the one-line message of this thread's last failed call into `buf` (at most
/// `len - 1` bytes and a terminating NUL; nothing when `buf` is NULL or `len` is 0) and
/// returns the message's whole length in bytes (without the NUL): call with `len` 0 to size a
/// buffer. The message stays until the next failed call.
///
/// # Safety
/// `buf` is NULL or points to `len` writable bytes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_last_error(buf: *mut c_char, len: usize) -> usize {
    last_error(|message| {
        let bytes = message.as_bytes();
        if !buf.is_null() && len > 0 {
            let n = bytes.len().min(len - 1);
            // SAFETY: `buf` has `len` writable bytes and `n + 1 <= len`.
            unsafe {
                core::ptr::copy_nonoverlapping(bytes.as_ptr().cast::<c_char>(), buf, n);
                *buf.add(n) = 0;
            }
        }
        bytes.len()
    })
}

/// A navigator for the rig whose file's text is the `rig_len` bytes at `rig` (TOML,
/// vehicle-interfaces.md section 3, or its JSON form, section 4; UTF-8, no NUL needed), with
/// the settings `stereonav replay` uses by default. On success `*out` is the new handle, which
/// the caller frees with `sn_navigator_free`; on an error `*out` is NULL.
///
/// Errors: `SN_E_NULL` (`rig` or `out` NULL), `SN_E_RIG` (not a rig file, or one the navigator
/// cannot use).
///
/// # Safety
/// `rig` points to `rig_len` readable bytes; `out` is NULL or points to a writable pointer.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_new(
    rig: *const c_char,
    rig_len: usize,
    out: *mut *mut sn_navigator,
) -> c_int {
    boundary("sn_navigator_new", || {
        // SAFETY: `out` is NULL or writable (the contract).
        let out = unsafe { non_null_mut(out, "out") }?;
        *out = core::ptr::null_mut();
        // SAFETY: `rig` has `rig_len` readable bytes (the contract).
        let text = unsafe { slice(rig.cast::<u8>(), rig_len, "rig") }?;
        if rig.is_null() {
            return Err(Failure::new(SN_E_NULL, "rig is NULL"));
        }
        let rig = parse_rig(text)?;
        let nav = Navigator::new(rig, NavSettings::default())
            .map_err(|e| Failure::new(SN_E_RIG, e.to_string()))?;
        *out = Box::into_raw(Box::new(sn_navigator {
            nav,
            inputs: Inputs::default(),
        }));
        Ok(())
    })
}

/// Frees a navigator (NULL: nothing).
///
/// # Safety
/// `nav` is NULL or a handle from `sn_navigator_new` not freed before.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_free(nav: *mut sn_navigator) {
    if !nav.is_null() {
        // SAFETY: a handle from `Box::into_raw` in `sn_navigator_new`, freed once.
        drop(unsafe { Box::from_raw(nav) });
    }
}

/// Adds an odometry sample: robot-frame velocities (m/s, m/s, rad/s; vehicle-interfaces.md
/// section 2) held from `t_us` (the board's clock, microseconds) until the next sample.
/// Samples come in time order, up to a frame's time before that frame.
///
/// Errors: `SN_E_NULL`, `SN_E_ARGUMENT` (a non-finite velocity), `SN_E_ORDER` (older than the
/// previous sample).
///
/// # Safety
/// `nav` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_push_odometry(
    nav: *mut sn_navigator,
    t_us: u64,
    vx: f64,
    vy: f64,
    vtheta: f64,
) -> c_int {
    boundary("sn_navigator_push_odometry", || {
        // SAFETY: NULL or a live handle.
        let nav = unsafe { non_null_mut(nav, "nav") }?;
        nav.inputs.odometry(t_us, vx, vy, vtheta)?;
        nav.run()
    })
}

/// Adds `len` bytes of the board's byte stream (board-icd.md section 3) in any chunking: a
/// packet may be split across calls; every frame completed by these bytes is processed, in
/// order, and counted in `*frames_done` (when not NULL). Corrupt packets and junk are skipped
/// and make the call return `SN_E_STREAM` after the good frames were processed.
///
/// Errors: `SN_E_NULL` (`nav`, or `bytes` with `len > 0`), `SN_E_STREAM` (corrupt packets or
/// junk skipped), `SN_E_ORDER` (a frame older than the previous one, skipped), `SN_E_REFUSED`.
///
/// # Safety
/// `nav` is NULL or a live handle; `bytes` points to `len` readable bytes; `frames_done` is
/// NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_push_stream(
    nav: *mut sn_navigator,
    bytes: *const u8,
    len: usize,
    frames_done: *mut usize,
) -> c_int {
    let mut done = 0;
    let code = boundary("sn_navigator_push_stream", || {
        // SAFETY: NULL or a live handle.
        let nav = unsafe { non_null_mut(nav, "nav") }?;
        // SAFETY: `len` readable bytes (the contract).
        let bytes = unsafe { slice(bytes, len, "bytes") }?;
        let taken = nav.inputs.stream(bytes, &mut done);
        let ran = nav.run();
        taken.and(ran)
    });
    // SAFETY: NULL or writable (the contract).
    if let Some(out) = unsafe { frames_done.as_mut() } {
        *out = done;
    }
    code
}

/// Processes one stereo frame given as the board's features (`n_left` at `left`, `n_right` at
/// `right`; either may be 0 with any pointer) at `t_us`, after the odometry up to `t_us`.
///
/// Errors: `SN_E_NULL` (`nav`, or a feature pointer NULL with a count), `SN_E_ORDER` (older
/// than the previous frame), `SN_E_REFUSED`.
///
/// # Safety
/// `nav` is NULL or a live handle; `left` and `right` point to `n_left` and `n_right`
/// readable features.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_push_frame(
    nav: *mut sn_navigator,
    t_us: u64,
    left: *const sn_feature,
    n_left: usize,
    right: *const sn_feature,
    n_right: usize,
) -> c_int {
    boundary("sn_navigator_push_frame", || {
        // SAFETY: NULL or a live handle.
        let nav = unsafe { non_null_mut(nav, "nav") }?;
        // SAFETY: the counts' readable features (the contract).
        let (l, r) = unsafe {
            (
                slice(left, n_left, "left")?,
                slice(right, n_right, "right")?,
            )
        };
        let frame = (
            l.iter().map(|f| Pixel::from_q4(f.x_q4, f.y_q4)).collect(),
            r.iter().map(|f| Pixel::from_q4(f.x_q4, f.y_q4)).collect(),
        );
        nav.inputs.frame(t_us, frame)?;
        nav.run()
    })
}

/// The end of the data, as `stereonav replay` ends a log: the bytes of a packet still
/// incomplete are decoded as far as they go, and phase 2 starts from phase 1's batch if it has
/// not started. Data may follow (phase 2 goes on).
///
/// Errors: `SN_E_NULL`, `SN_E_REFUSED` (the hand-over failed).
///
/// # Safety
/// `nav` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_finish(nav: *mut sn_navigator) -> c_int {
    boundary("sn_navigator_finish", || {
        // SAFETY: NULL or a live handle.
        let nav = unsafe { non_null_mut(nav, "nav") }?;
        let ended = nav.inputs.end();
        let ran = nav.run();
        let finished = nav
            .nav
            .finish()
            .map(|_| ())
            .map_err(|e| Failure::new(SN_E_REFUSED, e.to_string()));
        ended.and(ran).and(finished)
    })
}

/// Row-major 3x3 from nalgebra.
fn row_major(m: &nalgebra::Matrix3<f64>) -> [f64; 9] {
    let mut out = [0.0; 9];
    for (k, v) in out.iter_mut().enumerate() {
        *v = m[(k / 3, k % 3)];
    }
    out
}

/// The navigator's current pose (at its last frame) and covariance into `*out`; `phase` 0
/// while calibrating, 1 while navigating; `localized` 1.
///
/// Errors: `SN_E_NULL`.
///
/// # Safety
/// `nav` is NULL or a live handle; `out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_pose(nav: *const sn_navigator, out: *mut sn_pose) -> c_int {
    boundary("sn_navigator_pose", || {
        // SAFETY: NULL or a live handle; NULL or writable.
        let (nav, out) = unsafe { (non_null(nav, "nav")?, non_null_mut(out, "out")?) };
        let (pose, cov) = nav.nav.pose();
        *out = sn_pose {
            t_us: nav.nav.last_frame_t_us().unwrap_or(0),
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            cov: row_major(&cov),
            phase: i32::from(nav.nav.phase() == Phase::Navigating),
            localized: 1,
        };
        Ok(())
    })
}

/// The mapped landmarks (phase 2's map; none during phase 1), by id: `*count` is how many
/// there are, and the first `min(cap, *count)` are copied to `out` (`out` may be NULL when
/// `cap` is 0: call so to size a buffer).
///
/// Errors: `SN_E_NULL` (`nav`, `count`, or `out` with `cap > 0`).
///
/// # Safety
/// `nav` is NULL or a live handle; `out` points to `cap` writable landmarks; `count` is NULL
/// or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_landmarks(
    nav: *const sn_navigator,
    out: *mut sn_landmark,
    cap: usize,
    count: *mut usize,
) -> c_int {
    boundary("sn_navigator_landmarks", || {
        // SAFETY: NULL or a live handle; NULL or writable.
        let (nav, count) = unsafe { (non_null(nav, "nav")?, non_null_mut(count, "count")?) };
        *count = 0;
        if cap > 0 && out.is_null() {
            return Err(Failure::new(
                SN_E_NULL,
                format!("out is NULL with a capacity of {cap}"),
            ));
        }
        let Some(ekf) = nav.nav.ekf() else {
            return Ok(());
        };
        let mut all: Vec<sn_landmark> = ekf
            .landmarks()
            .map(|l| {
                let sd = |v: f64| if v >= 0.0 { libm::sqrt(v) } else { f64::NAN };
                sn_landmark {
                    id: u32::try_from(l.id.0).unwrap_or(u32::MAX),
                    x: l.position.x,
                    y: l.position.y,
                    z: l.position.z,
                    sigma: [
                        sd(l.covariance[(0, 0)]),
                        sd(l.covariance[(1, 1)]),
                        sd(l.covariance[(2, 2)]),
                    ],
                    observations: u32::try_from(l.observations).unwrap_or(u32::MAX),
                }
            })
            .collect();
        all.sort_by_key(|l| l.id);
        *count = all.len();
        for (k, l) in all.iter().take(cap).enumerate() {
            // SAFETY: `out` has `cap` writable landmarks and `k < cap`.
            unsafe { out.add(k).write(*l) };
        }
        Ok(())
    })
}

/// The current estimate of one parameter of the camera `C` or the vehicle `V` by its rig-file
/// name (`f`, `cx`, `cy`, `baseline`, `mount_x`, ..., `odom_scale`, `odom_yaw_scale`,
/// `odom_yaw_bias`, `time_offset`; a NUL-terminated string) into `*value` and its standard
/// deviation into `*sigma` (0 for a parameter held fixed).
///
/// Errors: `SN_E_NULL`, `SN_E_ARGUMENT` (not UTF-8, or no such parameter).
///
/// # Safety
/// `nav` is NULL or a live handle; `name` is NULL or a NUL-terminated string; `value` and
/// `sigma` are NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_navigator_parameter(
    nav: *const sn_navigator,
    name: *const c_char,
    value: *mut f64,
    sigma: *mut f64,
) -> c_int {
    boundary("sn_navigator_parameter", || {
        // SAFETY: NULL or live/writable (the contract).
        let (nav, value, sigma) = unsafe {
            (
                non_null(nav, "nav")?,
                non_null_mut(value, "value")?,
                non_null_mut(sigma, "sigma")?,
            )
        };
        if name.is_null() {
            return Err(Failure::new(SN_E_NULL, "name is NULL"));
        }
        // SAFETY: non-NULL and NUL-terminated (the contract).
        let name = unsafe { core::ffi::CStr::from_ptr(name) };
        let name = name
            .to_str()
            .map_err(|_| Failure::new(SN_E_ARGUMENT, "the parameter name is not UTF-8"))?;
        let param = Param::from_name(name).ok_or_else(|| {
            Failure::new(
                SN_E_ARGUMENT,
                format!("no parameter {name:?} (the rig file's names: f, cx, cy, baseline, mount_x, mount_y, mount_z, mount_roll, mount_pitch, mount_yaw, odom_scale, odom_yaw_scale, odom_yaw_bias, time_offset)"),
            )
        })?;
        let (camera, cov) = nav.nav.camera();
        let v = cov
            .get((param.index(), param.index()))
            .copied()
            .unwrap_or(0.0);
        *value = camera.get(param);
        *sigma = if v >= 0.0 { libm::sqrt(v) } else { f64::NAN };
        Ok(())
    })
}

/// A localiser on a saved map: the map file's `map_len` bytes at `map` (the project's map
/// format, docs/maps.md: `stereonav replay --save-map` or `stereonav map import`) and the rig
/// file's text (as for `sn_navigator_new`; its lens, image size and noise; the calibration
/// comes from the map). On success `*out` is the new handle, freed with `sn_localizer_free`;
/// on an error `*out` is NULL.
///
/// Errors: `SN_E_NULL`, `SN_E_RIG`, `SN_E_MAP` (not a map, damaged, or none of its lamps
/// usable).
///
/// # Safety
/// `rig` points to `rig_len` readable bytes, `map` to `map_len`; `out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_localizer_new(
    rig: *const c_char,
    rig_len: usize,
    map: *const u8,
    map_len: usize,
    out: *mut *mut sn_localizer,
) -> c_int {
    boundary("sn_localizer_new", || {
        // SAFETY: NULL or writable.
        let out = unsafe { non_null_mut(out, "out") }?;
        *out = core::ptr::null_mut();
        if rig.is_null() {
            return Err(Failure::new(SN_E_NULL, "rig is NULL"));
        }
        if map.is_null() {
            return Err(Failure::new(SN_E_NULL, "map is NULL"));
        }
        // SAFETY: the sizes' readable bytes (the contract).
        let (text, bytes) = unsafe {
            (
                slice(rig.cast::<u8>(), rig_len, "rig")?,
                slice(map, map_len, "map")?,
            )
        };
        let rig = parse_rig(text)?;
        #[cfg(feature = "std")]
        {
            let map = map_file::Map::from_bytes(bytes, "map")
                .map_err(|e| Failure::new(SN_E_MAP, e.to_string()))?;
            let settings = localize::LocalizerSettings::default();
            let loc = replay::localizer_for(&map, Some(rig), settings)
                .map_err(|e| Failure::new(SN_E_MAP, e.to_string()))?;
            *out = Box::into_raw(Box::new(sn_localizer {
                inner: LocalizerInner {
                    loc,
                    inputs: Inputs::default(),
                    last: None,
                },
            }));
            Ok(())
        }
        #[cfg(not(feature = "std"))]
        {
            let _ = (rig, bytes);
            Err(no_localizer())
        }
    })
}

/// Frees a localiser (NULL: nothing).
///
/// # Safety
/// `loc` is NULL or a handle from `sn_localizer_new` not freed before.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_localizer_free(loc: *mut sn_localizer) {
    if !loc.is_null() {
        // SAFETY: a handle from `Box::into_raw` in `sn_localizer_new`, freed once.
        drop(unsafe { Box::from_raw(loc) });
    }
}

/// Adds an odometry sample, as `sn_navigator_push_odometry`.
///
/// Errors: `SN_E_NULL`, `SN_E_ARGUMENT`, `SN_E_ORDER`.
///
/// # Safety
/// `loc` is NULL or a live handle.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_localizer_push_odometry(
    loc: *mut sn_localizer,
    t_us: u64,
    vx: f64,
    vy: f64,
    vtheta: f64,
) -> c_int {
    boundary("sn_localizer_push_odometry", || {
        // SAFETY: NULL or a live handle.
        let loc = unsafe { non_null_mut(loc, "loc") }?;
        #[cfg(feature = "std")]
        {
            loc.inner.inputs.odometry(t_us, vx, vy, vtheta)?;
            loc.inner.run()
        }
        #[cfg(not(feature = "std"))]
        {
            let _ = (loc, t_us, vx, vy, vtheta);
            Err(no_localizer())
        }
    })
}

/// Adds bytes of the board's stream, as `sn_navigator_push_stream`.
///
/// Errors: `SN_E_NULL`, `SN_E_STREAM`, `SN_E_ORDER`, `SN_E_REFUSED`.
///
/// # Safety
/// `loc` is NULL or a live handle; `bytes` points to `len` readable bytes; `frames_done` is
/// NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_localizer_push_stream(
    loc: *mut sn_localizer,
    bytes: *const u8,
    len: usize,
    frames_done: *mut usize,
) -> c_int {
    #[cfg_attr(not(feature = "std"), allow(unused_mut))]
    let mut done = 0;
    let code = boundary("sn_localizer_push_stream", || {
        // SAFETY: NULL or a live handle.
        let loc = unsafe { non_null_mut(loc, "loc") }?;
        // SAFETY: `len` readable bytes.
        let bytes = unsafe { slice(bytes, len, "bytes") }?;
        #[cfg(feature = "std")]
        {
            let taken = loc.inner.inputs.stream(bytes, &mut done);
            let ran = loc.inner.run();
            taken.and(ran)
        }
        #[cfg(not(feature = "std"))]
        {
            let _ = (loc, bytes);
            Err(no_localizer())
        }
    });
    // SAFETY: NULL or writable.
    if let Some(out) = unsafe { frames_done.as_mut() } {
        *out = done;
    }
    code
}

/// The localiser's pose at its last frame, in the map's frame, into `*out`: `localized` 1
/// while it stands behind the pose, 0 while lost (the pose is then its best guess, or zeros
/// with an infinite covariance when it has none); `phase` 1.
///
/// Errors: `SN_E_NULL`.
///
/// # Safety
/// `loc` is NULL or a live handle; `out` is NULL or writable.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn sn_localizer_pose(loc: *const sn_localizer, out: *mut sn_pose) -> c_int {
    boundary("sn_localizer_pose", || {
        // SAFETY: NULL or a live handle; NULL or writable.
        let (loc, out) = unsafe { (non_null(loc, "loc")?, non_null_mut(out, "out")?) };
        let none = sn_pose {
            t_us: 0,
            cov: [
                f64::INFINITY,
                0.0,
                0.0,
                0.0,
                f64::INFINITY,
                0.0,
                0.0,
                0.0,
                f64::INFINITY,
            ],
            phase: 1,
            ..sn_pose::default()
        };
        #[cfg(not(feature = "std"))]
        {
            let _ = (loc, none, out);
            return Err(no_localizer());
        }
        #[cfg(feature = "std")]
        let last = &loc.inner.last;
        #[cfg(feature = "std")]
        {
            *out = match last {
                None => none,
                Some(r) => match r.pose {
                    None => sn_pose {
                        t_us: r.t_us,
                        ..none
                    },
                    Some(p) => sn_pose {
                        t_us: r.t_us,
                        x: p.x,
                        y: p.y,
                        theta: p.theta,
                        cov: row_major(&r.pose_covariance),
                        phase: 1,
                        localized: i32::from(r.status == localize::Status::Localized),
                    },
                },
            };
            Ok(())
        }
    })
}

/// Firmware without an operating system (`--no-default-features --features firmware`): the
/// heap is the firmware's (`sn_firmware_alloc`, `sn_firmware_free`) and a panic, which only a
/// bug can raise, ends in the firmware's `sn_firmware_panic` with its message (the library is
/// built with `panic = "abort"`: nothing unwinds into C). The three are declared at the end
/// of the header.
#[cfg(all(not(feature = "std"), feature = "firmware"))]
mod firmware {
    use core::alloc::{GlobalAlloc, Layout};
    use core::ffi::{c_char, c_void};

    unsafe extern "C" {
        /// Firmware without an operating system (the library built with `cargo build
        /// --release -p stereonav-capi --no-default-features --features firmware` and
        /// `panic = "abort"`, as ci/nostd-proof builds it) takes its memory from the firmware,
        /// which defines this and the next two (the hosted build never calls them): `size`
        /// bytes aligned to `align` (a power of two), or NULL when there is no memory.
        fn sn_firmware_alloc(size: usize, align: usize) -> *mut c_void;
        /// Frees what `sn_firmware_alloc` returned, with its size and alignment (firmware
        /// builds only).
        fn sn_firmware_free(ptr: *mut c_void, size: usize, align: usize);
        /// A bug in the library: `len` bytes of message, not NUL-terminated; should not
        /// return (reset the stack). Firmware builds only; without `std` the localiser's
        /// functions answer `SN_E_REFUSED` and the last error is one for the program.
        fn sn_firmware_panic(message: *const c_char, len: usize);
    }

    /// The firmware's allocation functions as Rust's global allocator.
    struct Firmware;

    // SAFETY: the firmware's functions return NULL or `size` bytes aligned to `align` that
    // stay valid until freed (the header's contract for them).
    unsafe impl GlobalAlloc for Firmware {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            // SAFETY: the firmware's function, with the layout's size and alignment.
            unsafe { sn_firmware_alloc(layout.size(), layout.align()).cast() }
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: `ptr` came from `alloc` with this layout.
            unsafe { sn_firmware_free(ptr.cast(), layout.size(), layout.align()) }
        }
    }

    #[global_allocator]
    static ALLOCATOR: Firmware = Firmware;

    /// A panic's message into a fixed buffer (no heap: the heap may be what failed).
    struct Message {
        buf: [u8; 256],
        len: usize,
    }

    impl core::fmt::Write for Message {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            for &b in s.as_bytes() {
                if let Some(slot) = self.buf.get_mut(self.len) {
                    *slot = b;
                    self.len += 1;
                }
            }
            Ok(())
        }
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
        let mut m = Message {
            buf: [0; 256],
            len: 0,
        };
        let _ = core::fmt::write(&mut m, format_args!("{info}"));
        // SAFETY: the firmware's function, with `len` readable bytes.
        unsafe { sn_firmware_panic(m.buf.as_ptr().cast(), m.len) };
        loop {
            core::hint::spin_loop();
        }
    }
}
