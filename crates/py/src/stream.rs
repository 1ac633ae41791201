//! The board's feature stream (`board-icd.md` section 3) for Python: a push decoder and the
//! board's packet encoder.

use fpga_link::{Decoder, Event, Feature, Header, MAX_PACKET_LEN};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyBytes;

use crate::{FEATURE_RECORD_BYTES, input_error};

/// A decoded frame as plain data, the records packed as in the wire format.
type OwnedFrame = (u32, u64, u8, u32, Vec<u8>, Vec<u8>);

/// `stereonav._arrays`, the module of the package's NumPy dtypes.
const ARRAYS_MODULE: &str = "stereonav._arrays";
/// Its dtype of one feature record.
const FEATURE_DTYPE: &str = "FEATURE_DTYPE";
/// `stereonav._arrays.FEATURE_DTYPE`, imported on first use.
static FEATURE_DTYPE_OBJECT: PyOnceLock<Py<PyAny>> = PyOnceLock::new();

/// One good packet: a stereo frame's features as the board sent them (`board-icd.md`
/// section 3).
#[pyclass(module = "stereonav._native", frozen, get_all)]
pub(crate) struct Frame {
    /// Frame counter (u32, +1 per stereo frame, wraps).
    frame: u32,
    /// Mid-exposure timestamp, microseconds, on the vehicle's clock.
    t_us: u64,
    /// Bit 0: the left camera overflowed `MAX_FEATURES`; bit 1: the right one did.
    flags: u8,
    /// Frames lost just before this one (gap in counters modulo 2**32).
    lost_before: u32,
    /// The left camera's features, `(N,)` of `FEATURE_DTYPE`, in the board's order.
    left: Py<PyAny>,
    /// The right camera's features, `(N,)` of `FEATURE_DTYPE`, in the board's order.
    right: Py<PyAny>,
}

#[pymethods]
impl Frame {
    /// Whether the left camera had more features than `MAX_FEATURES`.
    #[getter]
    fn left_overflow(&self) -> bool {
        self.flags & 1 != 0
    }

    /// Whether the right camera had more features than `MAX_FEATURES`.
    #[getter]
    fn right_overflow(&self) -> bool {
        self.flags & 2 != 0
    }

    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        Ok(format!(
            "Frame(frame={}, t_us={}, flags={}, lost_before={}, left={}, right={})",
            self.frame,
            self.t_us,
            self.flags,
            self.lost_before,
            self.left.bind(py).repr()?,
            self.right.bind(py).repr()?,
        ))
    }
}

fn own(frame: &fpga_link::Frame<'_>) -> OwnedFrame {
    let records = frame.feature_bytes();
    let split = usize::from(frame.header().n_left) * FEATURE_RECORD_BYTES;
    let (left, right) = records.split_at(split.min(records.len()));
    (
        frame.frame(),
        frame.t_us(),
        frame.flags(),
        frame.lost_before(),
        left.to_vec(),
        right.to_vec(),
    )
}

/// A frame's packed records as a `(N,)` array of `stereonav._arrays.FEATURE_DTYPE`.
pub(crate) fn feature_array(py: Python<'_>, records: Vec<u8>) -> PyResult<Py<PyAny>> {
    let dtype = FEATURE_DTYPE_OBJECT.import(py, ARRAYS_MODULE, FEATURE_DTYPE)?;
    Ok(PyArray1::from_vec(py, records)
        .call_method1("view", (dtype,))?
        .unbind())
}

fn to_python(py: Python<'_>, frames: Vec<OwnedFrame>) -> PyResult<Vec<Frame>> {
    frames
        .into_iter()
        .map(|(frame, t_us, flags, lost_before, left, right)| {
            Ok(Frame {
                frame,
                t_us,
                flags,
                lost_before,
                left: feature_array(py, left)?,
                right: feature_array(py, right)?,
            })
        })
        .collect()
}

/// Push decoder of the board's byte stream. `push(data)` returns the frames completed by
/// `data`; `finish()` ends the stream and returns the frames found inside a packet cut off by
/// the end. Corrupt packets and garbage are skipped and counted in `stats`.
#[pyclass(module = "stereonav._native")]
pub(crate) struct StreamDecoder {
    decoder: Box<Decoder>,
}

#[pymethods]
impl StreamDecoder {
    #[new]
    fn new() -> Self {
        Self {
            decoder: Box::new(Decoder::new()),
        }
    }

    /// Decodes a chunk of the stream (any size); returns the frames it completed. The GIL is
    /// released.
    fn push(&mut self, py: Python<'_>, data: &[u8]) -> PyResult<Vec<Frame>> {
        let decoder = &mut self.decoder;
        let frames = py.detach(|| {
            let mut frames = Vec::new();
            let mut rest = data;
            loop {
                let (used, event) = decoder.decode(rest);
                rest = rest.get(used..).unwrap_or_default();
                match event {
                    Some(Event::Frame(frame)) => frames.push(own(&frame)),
                    Some(Event::Corrupt(_)) => {}
                    None => break,
                }
            }
            frames
        });
        to_python(py, frames)
    }

    /// Ends the stream: a packet still incomplete is corrupt and its inside is searched.
    fn finish(&mut self, py: Python<'_>) -> PyResult<Vec<Frame>> {
        let mut frames = Vec::new();
        while let Some(event) = self.decoder.decode_end() {
            if let Event::Frame(frame) = event {
                frames.push(own(&frame));
            }
        }
        to_python(py, frames)
    }

    /// `(packets, corrupt, lost, bytes_skipped)` so far.
    #[getter]
    fn stats(&self) -> (u64, u64, u64, u64) {
        let s = self.decoder.stats();
        (s.packets, s.corrupt, s.lost, s.bytes_skipped)
    }

    /// Bytes held waiting for the rest of a packet.
    #[getter]
    fn buffered(&self) -> usize {
        self.decoder.buffered()
    }
}

fn features_from_records(side: &str, records: &[u8]) -> Result<Vec<Feature>, String> {
    if !records.len().is_multiple_of(FEATURE_RECORD_BYTES) {
        return Err(format!(
            "{side} records have {} bytes, not a multiple of {FEATURE_RECORD_BYTES}",
            records.len()
        ));
    }
    Ok(records
        .chunks_exact(FEATURE_RECORD_BYTES)
        .map(|r| Feature {
            x_q4: u16::from_le_bytes([r[0], r[1]]),
            y_q4: u16::from_le_bytes([r[2], r[3]]),
            r: i32::from_le_bytes([r[4], r[5], r[6], r[7]]),
        })
        .collect())
}

/// One packet as the board writes it: `frame` counter, `t_us` timestamp, `flags` (bit 0 left
/// overflow, bit 1 right overflow) and the packed left and right feature records. Returns the
/// packet's bytes; raises `stereonav.InputError` for more than 1023 features a side, reserved
/// flag bits, or records that are not whole.
#[pyfunction]
pub(crate) fn encode_packet<'py>(
    py: Python<'py>,
    frame: u32,
    t_us: u64,
    flags: u8,
    left: &[u8],
    right: &[u8],
) -> PyResult<Bound<'py, PyBytes>> {
    let left = features_from_records("left", left).map_err(|m| input_error(py, m))?;
    let right = features_from_records("right", right).map_err(|m| input_error(py, m))?;
    let header = Header {
        flags,
        frame,
        t_us,
        ..Header::default()
    };
    let mut out = vec![0u8; MAX_PACKET_LEN];
    let n = fpga_link::encode_packet(&header, &left, &right, &mut out)
        .map_err(|e| input_error(py, e.to_string()))?;
    Ok(PyBytes::new(py, out.get(..n).unwrap_or_default()))
}
