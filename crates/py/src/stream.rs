//! The board's feature stream (`board-icd.md` section 3) for Python: a push decoder and the
//! board's packet encoder.

use fpga_link::{Decoder, Event, Feature, Header, MAX_PACKET_LEN};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::{FEATURE_RECORD_BYTES, input_error};

/// A decoded frame as plain data: `(frame, t_us, flags, lost_before, left_records,
/// right_records)`, the records packed as in the wire format.
type OwnedFrame = (u32, u64, u8, u32, Vec<u8>, Vec<u8>);
/// The same, handed to Python with the records as 1-D `uint8` arrays.
type PyFrame<'py> = (
    u32,
    u64,
    u8,
    u32,
    Bound<'py, PyArray1<u8>>,
    Bound<'py, PyArray1<u8>>,
);

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

fn to_python(py: Python<'_>, frames: Vec<OwnedFrame>) -> Vec<PyFrame<'_>> {
    frames
        .into_iter()
        .map(|(frame, t_us, flags, lost, left, right)| {
            (
                frame,
                t_us,
                flags,
                lost,
                PyArray1::from_vec(py, left),
                PyArray1::from_vec(py, right),
            )
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

    /// Decodes a chunk of the stream (any size); returns the frames it completed as tuples
    /// `(frame, t_us, flags, lost_before, left_records, right_records)`. The GIL is released.
    fn push<'py>(&mut self, py: Python<'py>, data: &[u8]) -> Vec<PyFrame<'py>> {
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
    fn finish<'py>(&mut self, py: Python<'py>) -> Vec<PyFrame<'py>> {
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
