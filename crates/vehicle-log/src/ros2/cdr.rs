//! CDR, the encoding of ROS 2 messages (OMG DDS-XTypes, "plain" CDR as the ROS 2 middlewares
//! write it), decoded by the message's schema.
//!
//! Our own decoder, not a crate's: the Rust CDR crates (`cdr-encoding`, `cdr`) decode into
//! types fixed at compile time through serde, but a bag's layout is the one its schema states
//! (vehicle-interfaces.md 4.1: schemas read from the file, not assumed), so the decoder must
//! walk the schema's fields at run time; and an image's pixels are borrowed from the message,
//! not copied element by element.
//!
//! A message starts with a 4-byte encapsulation header: `00 00` big-endian or `00 01`
//! little-endian CDR (XCDR1, what ROS 2 writes), or `00 06` / `00 07` plain XCDR2 (8-byte
//! values aligned to 4); two option bytes follow. After it, each primitive is aligned to its
//! size (at most the encoding's largest alignment) counted from the byte after the header; a
//! string is a `uint32` length counting its terminating NUL, then the bytes; a sequence a
//! `uint32` count, then the elements; a fixed array its elements alone; a nested message its
//! fields in order.

use super::msgdef::{Array, Base, Field, MsgDefs, Prim};

/// A decoded value; arrays of 8-bit values stay bytes borrowed from the message.
#[derive(Debug, Clone, PartialEq)]
pub enum Value<'a> {
    /// `bool`.
    Bool(bool),
    /// A signed integer.
    Int(i64),
    /// An unsigned integer.
    UInt(u64),
    /// A float.
    Float(f64),
    /// A string (without its NUL); lossy where the bytes are not UTF-8.
    Str(String),
    /// An array of `uint8`, `byte`, `char` or `int8`.
    Bytes(&'a [u8]),
    /// Any other array.
    Array(Vec<Value<'a>>),
    /// A message: its fields' values in the schema's order.
    Msg(Vec<Value<'a>>),
}

impl<'a> Value<'a> {
    /// The value at `indices` (from [`MsgDefs::resolve`]) inside this message.
    pub fn at(&self, indices: &[usize]) -> Option<&Value<'a>> {
        let mut v = self;
        for &i in indices {
            match v {
                Value::Msg(fields) => v = fields.get(i)?,
                _ => return None,
            }
        }
        Some(v)
    }
}

/// Decodes `data`, one CDR message of the schema's root type. Errors name the problem and
/// the field.
pub fn decode<'a>(defs: &MsgDefs, data: &'a [u8]) -> Result<Value<'a>, String> {
    let header = data
        .get(..4)
        .ok_or_else(|| format!("{} bytes: shorter than the CDR header", data.len()))?;
    let (little, max_align) = match (header[0], header[1]) {
        (0, 0) => (false, 8),
        (0, 1) => (true, 8),
        (0, 6) => (false, 4),
        (0, 7) => (true, 4),
        (a, b) => {
            return Err(format!(
                "encapsulation {a:02x} {b:02x} is not plain CDR (00 00, 00 01, 00 06 or 00 07)"
            ));
        }
    };
    let mut reader = Reader {
        body: &data[4..],
        pos: 0,
        little,
        max_align,
        // Every value but an empty message's takes a byte: more values than bytes (and a
        // margin for empty messages) is a schema built to blow up, not a message.
        budget: data.len().saturating_mul(2).saturating_add(4096),
    };
    let fields = defs
        .fields(defs.root())
        .ok_or_else(|| format!("type {} not defined", defs.root()))?;
    reader.message(defs, fields, 0)
}

struct Reader<'a> {
    body: &'a [u8],
    pos: usize,
    little: bool,
    max_align: usize,
    /// Values still allowed.
    budget: usize,
}

impl<'a> Reader<'a> {
    fn align(&mut self, size: usize) {
        let a = size.min(self.max_align);
        self.pos = self.pos.div_ceil(a) * a;
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.body.len());
        let Some(end) = end else {
            return Err(format!(
                "the message ends at byte {} of {} needed",
                self.body.len() + 4,
                self.pos.saturating_add(n).saturating_add(4)
            ));
        };
        let s = &self.body[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn fixed<const N: usize>(&mut self) -> Result<[u8; N], String> {
        self.align(N);
        let mut b = [0u8; N];
        b.copy_from_slice(self.take(N)?);
        if self.little {
            b.reverse();
        }
        // `b` is now big-endian.
        Ok(b)
    }

    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_be_bytes(self.fixed()?))
    }

    fn prim(&mut self, p: Prim) -> Result<Value<'a>, String> {
        Ok(match p {
            Prim::Bool => Value::Bool(self.take(1)?[0] != 0),
            Prim::U8 => Value::UInt(u64::from(self.take(1)?[0])),
            Prim::I8 => Value::Int(i64::from(i8::from_be_bytes([self.take(1)?[0]]))),
            Prim::I16 => Value::Int(i64::from(i16::from_be_bytes(self.fixed()?))),
            Prim::U16 => Value::UInt(u64::from(u16::from_be_bytes(self.fixed()?))),
            Prim::I32 => Value::Int(i64::from(i32::from_be_bytes(self.fixed()?))),
            Prim::U32 => Value::UInt(u64::from(self.u32()?)),
            Prim::I64 => Value::Int(i64::from_be_bytes(self.fixed()?)),
            Prim::U64 => Value::UInt(u64::from_be_bytes(self.fixed()?)),
            Prim::F32 => Value::Float(f64::from(f32::from_be_bytes(self.fixed()?))),
            Prim::F64 => Value::Float(f64::from_be_bytes(self.fixed()?)),
            Prim::String => {
                let n = self.u32()? as usize;
                let bytes = self.take(n)?;
                let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
                Value::Str(String::from_utf8_lossy(text).into_owned())
            }
            Prim::WString => {
                // A length in characters, then 4 bytes each (Fast-CDR's wchar_t); kept as
                // its count only: no field this stack reads is a wstring.
                let n = self.u32()? as usize;
                self.align(4);
                self.take(n.checked_mul(4).ok_or("wstring length overflows")?)?;
                Value::Str(String::new())
            }
        })
    }

    fn element(&mut self, defs: &MsgDefs, base: &Base, depth: usize) -> Result<Value<'a>, String> {
        self.budget = self
            .budget
            .checked_sub(1)
            .ok_or("more values than the message has bytes for")?;
        match base {
            Base::Prim(p) => self.prim(*p),
            Base::Msg(m) => {
                let fields = defs
                    .fields(m)
                    .ok_or_else(|| format!("type {m} not defined"))?;
                self.message(defs, fields, depth + 1)
            }
        }
    }

    fn field(&mut self, defs: &MsgDefs, field: &Field, depth: usize) -> Result<Value<'a>, String> {
        let count = match field.array {
            Array::No => return self.element(defs, &field.base, depth),
            Array::Fixed(n) => n,
            Array::Sequence => self.u32()? as usize,
        };
        if let Base::Prim(Prim::U8 | Prim::I8 | Prim::Bool) = field.base {
            return Ok(Value::Bytes(self.take(count)?));
        }
        // Every element takes at least a byte: a count past the message's end is damage, not
        // a reason to reserve gigabytes.
        let left = self.body.len().saturating_sub(self.pos);
        if count > left {
            return Err(format!("{count} elements but {left} bytes left"));
        }
        let mut values = Vec::with_capacity(count);
        for _ in 0..count {
            values.push(self.element(defs, &field.base, depth)?);
        }
        Ok(Value::Array(values))
    }

    fn message(
        &mut self,
        defs: &MsgDefs,
        fields: &[Field],
        depth: usize,
    ) -> Result<Value<'a>, String> {
        if depth > super::msgdef::MAX_DEPTH {
            return Err("types nest too deep".to_owned());
        }
        let mut values = Vec::with_capacity(fields.len());
        for field in fields {
            let v = self
                .field(defs, field, depth)
                .map_err(|e| format!("field {}: {e}", field.name))?;
            values.push(v);
        }
        Ok(Value::Msg(values))
    }
}
