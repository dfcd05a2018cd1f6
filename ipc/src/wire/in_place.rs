//! Decoding events and calls in place: the one hand-written decoder of the two bodies that
//! travel on every round trip, [`EventMsg`](super::EventMsg) and [`CallMsg`](super::CallMsg).
//!
//! bincode 2 decodes into new values only: a received call or event costs an allocation for its
//! name, one for its list of values, one for each text and each list of floats, and as many
//! frees once it is handled. A receiver on the critical path (the player takes an event, looks
//! its name up and copies its values into the engine; a program takes a call) needs none of
//! them: [`decode_event_in_place`] lends the name from the received bytes and writes the values
//! into the caller's vector, [`decode_call_into`] writes the function's name and the arguments
//! into the caller's `String` and vector, reusing the texts and lists already there.
//!
//! Both bodies are laid out alike (a text, then a sequence of [`Value`]s), as bincode's
//! configuration of this crate writes them (`wire::CONFIG`: little endian, variable-length
//! integers, a limit of [`MAX_BODY_LEN`]):
//!
//! - an unsigned integer (a length, a variant index) is one byte up to 250; or 251, 252, 253
//!   followed by 2, 4 or 8 bytes; a signed one is zigzag-mapped first (0, -1, 1, -2...);
//! - a text is its length in bytes then its UTF-8 bytes; a sequence is its length then its
//!   items;
//! - a [`Value`] is its variant index (`Int` 0, `Float` 1, `Bool` 2, `Text` 3, `FloatList` 4)
//!   then its content: a signed integer, 8 bytes of float, one byte 0 or 1, a text, a sequence
//!   of 8-byte floats.
//!
//! The decoder refuses what bincode refuses with bincode's own error, to the field: the
//! journal's and the acknowledgements' reasons stay the same text whichever decoder read the
//! body. That includes bincode's bookkeeping of its limit (each integer, float and byte
//! "claims" its size in memory, a sequence claims its items' size before it reads them and
//! gives each back as it decodes it, and decoding fails once the claims exceed the limit) and
//! the error its fast path gives for a 128-bit integer marker. The tests compare the two on
//! many generated, corrupt and truncated bodies.

use bincode::error::{AllowedEnumVariants, DecodeError, IntegerType};

use super::{WireError, MAX_BODY_LEN};
use crate::wire::Value;

/// The variants of [`Value`], as bincode's derived decoder names them in an error.
static VALUE_VARIANTS: AllowedEnumVariants = AllowedEnumVariants::Range { min: 0, max: 4 };

/// Decodes an [`EventMsg`](super::EventMsg) body without building one: returns the event's
/// name, borrowed from `bytes`, and writes its parameters into `params` (its previous content
/// replaced; a text or a list of floats in the same position reuses its buffer, and `params`
/// keeps its capacity).
///
/// Accepts and refuses exactly what [`decode`](super::decode)`::<EventMsg>` does, with the same
/// error. After an error `params` holds valid values but not the event's.
pub fn decode_event_in_place<'a>(
    bytes: &'a [u8],
    params: &mut Vec<Value>,
) -> Result<&'a str, WireError> {
    named_values(bytes, params)
}

/// Decodes a [`CallMsg`](super::CallMsg) body into `function` (the function's name) and
/// `args` (the arguments), reusing their buffers: a text or a list of floats in the same
/// position of `args` reuses its own.
///
/// Accepts and refuses exactly what [`decode`](super::decode)`::<CallMsg>` does, with the same
/// error. After an error `function` and `args` hold valid values but not the call's.
pub fn decode_call_into(
    bytes: &[u8],
    function: &mut String,
    args: &mut Vec<Value>,
) -> Result<(), WireError> {
    let name = named_values(bytes, args)?;
    function.clear();
    function.push_str(name);
    Ok(())
}

/// A text then a sequence of values, the whole of `bytes`: the layout of both bodies.
fn named_values<'a>(bytes: &'a [u8], values: &mut Vec<Value>) -> Result<&'a str, WireError> {
    if bytes.len() > MAX_BODY_LEN {
        return Err(WireError::TooLarge {
            len: bytes.len(),
            max: MAX_BODY_LEN,
        });
    }
    let mut reader = Reader {
        rest: bytes,
        claimed: 0,
    };
    let name = reader.text().map_err(WireError::Decode)?;
    reader.values_into(values).map_err(WireError::Decode)?;
    if !reader.rest.is_empty() {
        return Err(WireError::TrailingBytes {
            used: bytes.len() - reader.rest.len(),
            len: bytes.len(),
        });
    }
    Ok(name)
}

/// The bytes not read yet, and bincode's count of the memory its decoding claimed.
struct Reader<'a> {
    rest: &'a [u8],
    claimed: usize,
}

impl<'a> Reader<'a> {
    /// bincode's `claim_bytes_read`: fails once the claims exceed the limit.
    fn claim(&mut self, n: usize) -> Result<(), DecodeError> {
        // A match rather than `ok_or`, which would build (and drop) an error every time.
        match self.claimed.checked_add(n) {
            Some(claimed) if claimed <= MAX_BODY_LEN => {
                self.claimed = claimed;
                Ok(())
            }
            _ => Err(DecodeError::LimitExceeded),
        }
    }

    /// bincode's `claim_container_read`: `len` items of `size` bytes each.
    fn claim_items(&mut self, len: usize, size: usize) -> Result<(), DecodeError> {
        match len.checked_mul(size) {
            Some(n) => self.claim(n),
            None => Err(DecodeError::LimitExceeded),
        }
    }

    /// bincode's `unclaim_bytes_read`, after an item of a sequence claimed before. Never goes
    /// below zero: a sequence gives back at most what it claimed.
    fn unclaim(&mut self, n: usize) {
        self.claimed = self.claimed.saturating_sub(n);
    }

    /// The next `n` bytes, or bincode's error for a body that ends before them.
    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        if n > self.rest.len() {
            return Err(DecodeError::UnexpectedEnd {
                additional: n - self.rest.len(),
            });
        }
        let (head, rest) = self.rest.split_at(n);
        self.rest = rest;
        Ok(head)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    fn byte(&mut self) -> Result<u8, DecodeError> {
        Ok(self.array::<1>()?[0])
    }

    /// A variable-length unsigned integer of at most `max` bytes after its marker (4: a `u32`,
    /// 8: a `u64`). `fast` is the type bincode names as expected in the error for a marker of a
    /// larger type: bincode's `u64` decoder names `u32` there when at least 9 bytes remain (its
    /// fast path) and `u64` otherwise; its `u32` decoder always names `u32`.
    fn varint(
        &mut self,
        max: usize,
        fast: IntegerType,
        slow: IntegerType,
    ) -> Result<u64, DecodeError> {
        let expected = if self.rest.len() > max { fast } else { slow };
        let marker = self.byte()?;
        match marker {
            0..=250 => Ok(u64::from(marker)),
            251 => Ok(u64::from(u16::from_le_bytes(self.array()?))),
            252 => Ok(u64::from(u32::from_le_bytes(self.array()?))),
            253 if max == 8 => Ok(u64::from_le_bytes(self.array()?)),
            253 => Err(DecodeError::InvalidIntegerType {
                expected,
                found: IntegerType::U64,
            }),
            254 => Err(DecodeError::InvalidIntegerType {
                expected,
                found: IntegerType::U128,
            }),
            255 => Err(DecodeError::InvalidIntegerType {
                expected,
                found: IntegerType::Reserved,
            }),
        }
    }

    fn u64(&mut self) -> Result<u64, DecodeError> {
        self.claim(8)?;
        self.varint(8, IntegerType::U32, IntegerType::U64)
    }

    fn u32(&mut self) -> Result<u32, DecodeError> {
        self.claim(4)?;
        // A `u32` marker (252) is the largest `varint(4, ..)` accepts.
        self.varint(4, IntegerType::U32, IntegerType::U32)
            .map(|v| v as u32)
    }

    fn i64(&mut self) -> Result<i64, DecodeError> {
        self.claim(8)?;
        let n = self
            .varint(8, IntegerType::U32, IntegerType::U64)
            .map_err(|e| match e {
                DecodeError::InvalidIntegerType { expected, found } => {
                    DecodeError::InvalidIntegerType {
                        expected: signed(expected),
                        found: signed(found),
                    }
                }
                other => other,
            })?;
        // Zigzag: 0, -1, 1, -2, 2...
        Ok(((n >> 1) as i64) ^ -((n & 1) as i64))
    }

    /// The length of a sequence or a text.
    fn len(&mut self) -> Result<usize, DecodeError> {
        let v = self.u64()?;
        usize::try_from(v).map_err(|_| DecodeError::OutsideUsizeRange(v))
    }

    /// A text, borrowed.
    fn text(&mut self) -> Result<&'a str, DecodeError> {
        let len = self.len()?;
        self.claim_items(len, 1)?;
        let bytes = self.take(len)?;
        std::str::from_utf8(bytes).map_err(|inner| DecodeError::Utf8 { inner })
    }

    /// A sequence of values into `out`, reusing what it holds.
    fn values_into(&mut self, out: &mut Vec<Value>) -> Result<(), DecodeError> {
        const SIZE: usize = std::mem::size_of::<Value>();
        let len = self.len()?;
        self.claim_items(len, SIZE)?;
        out.truncate(len);
        out.reserve(len - out.len());
        for i in 0..len {
            self.unclaim(SIZE);
            match out.get_mut(i) {
                Some(slot) => self.value_into(slot)?,
                None => {
                    let mut value = Value::Bool(false);
                    self.value_into(&mut value)?;
                    out.push(value);
                }
            }
        }
        Ok(())
    }

    /// One value into `slot`: a text or a list of floats replacing one reuses its buffer.
    fn value_into(&mut self, slot: &mut Value) -> Result<(), DecodeError> {
        match self.u32()? {
            0 => *slot = Value::Int(self.i64()?),
            1 => {
                self.claim(8)?;
                *slot = Value::Float(f64::from_le_bytes(self.array()?));
            }
            2 => {
                self.claim(1)?;
                *slot = Value::Bool(match self.byte()? {
                    0 => false,
                    1 => true,
                    x => return Err(DecodeError::InvalidBooleanValue(x)),
                });
            }
            3 => {
                let text = self.text()?;
                match slot {
                    Value::Text(t) => {
                        t.clear();
                        t.push_str(text);
                    }
                    _ => *slot = Value::Text(text.to_owned()),
                }
            }
            4 => {
                let floats = self.floats()?;
                let floats = floats
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]));
                match slot {
                    Value::FloatList(l) => {
                        l.clear();
                        l.extend(floats);
                    }
                    _ => *slot = Value::FloatList(floats.collect()),
                }
            }
            found => {
                return Err(DecodeError::UnexpectedVariant {
                    type_name: "Value",
                    allowed: &VALUE_VARIANTS,
                    found,
                })
            }
        }
        Ok(())
    }

    /// The bytes of a sequence of floats, 8 each.
    fn floats(&mut self) -> Result<&'a [u8], DecodeError> {
        let len = self.len()?;
        self.claim_items(len, 8)?;
        // bincode gives back and claims again 8 bytes per float (never over the limit, as the
        // sequence claimed them all first), and reads them one by one: a body that ends inside
        // the list misses the rest of the first float it cannot read whole.
        let whole = len * 8;
        if whole > self.rest.len() {
            return Err(DecodeError::UnexpectedEnd {
                additional: 8 - self.rest.len() % 8,
            });
        }
        self.take(whole)
    }
}

/// bincode's name of a signed integer's type in an error about its unsigned encoding.
fn signed(t: IntegerType) -> IntegerType {
    match t {
        IntegerType::U8 => IntegerType::I8,
        IntegerType::U16 => IntegerType::I16,
        IntegerType::U32 => IntegerType::I32,
        IntegerType::U64 => IntegerType::I64,
        IntegerType::U128 => IntegerType::I128,
        IntegerType::Usize => IntegerType::Isize,
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{decode, encode_into, encoded_len, CallMsg, EventMsg};

    /// xorshift: deterministic pseudo-random numbers, the same cases on every run.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }

        fn below(&mut self, n: u64) -> u64 {
            self.next() % n
        }

        /// Lengths that cross the varint markers' thresholds now and then.
        fn len(&mut self, max: u64) -> usize {
            match self.below(10) {
                0 => 0,
                1 => 250 + self.below(3) as usize,
                2 => self.below(max) as usize,
                _ => self.below(8) as usize,
            }
        }

        fn text(&mut self) -> String {
            const PIECES: [&str; 6] = ["a", "Z", "_", "é", "飛", "🚀"];
            let n = self.len(300);
            (0..n).map(|_| PIECES[self.below(6) as usize]).collect()
        }

        fn int(&mut self) -> i64 {
            const EDGES: [i64; 12] = [
                0,
                -1,
                125,
                -126,
                126,
                32_767,
                -32_769,
                2_147_483_647,
                -2_147_483_649,
                i64::MAX,
                i64::MIN,
                250,
            ];
            match self.below(3) {
                0 => EDGES[self.below(12) as usize],
                1 => self.below(1000) as i64 - 500,
                _ => self.next() as i64,
            }
        }

        fn value(&mut self) -> Value {
            match self.below(5) {
                0 => Value::Int(self.int()),
                1 => Value::Float(f64::from_bits(self.next())),
                2 => Value::Bool(self.below(2) == 1),
                3 => Value::Text(self.text()),
                _ => {
                    let n = self.len(400);
                    Value::FloatList((0..n).map(|_| f64::from_bits(self.next())).collect())
                }
            }
        }

        fn values(&mut self) -> Vec<Value> {
            let n = self.len(40);
            (0..n).map(|_| self.value()).collect()
        }
    }

    fn encode<M: crate::wire::Message>(msg: &M) -> Vec<u8> {
        let mut buf = vec![0u8; encoded_len(msg).unwrap()];
        encode_into(msg, &mut buf).unwrap();
        buf
    }

    /// Both decoders on `bytes`: the same event (to the bit: compared re-encoded) or the same
    /// error; the same for the call, which has the same layout.
    fn agree(bytes: &[u8], params: &mut Vec<Value>, function: &mut String, args: &mut Vec<Value>) {
        match (
            decode::<EventMsg>(bytes),
            decode_event_in_place(bytes, params),
        ) {
            (Ok(reference), Ok(name)) => {
                assert_eq!(name, reference.name, "{bytes:?}");
                let ours = EventMsg::new(name, params.clone());
                assert_eq!(encode(&ours), encode(&reference), "{bytes:?}");
            }
            (Err(reference), Err(ours)) => {
                assert_eq!(format!("{ours:?}"), format!("{reference:?}"), "{bytes:?}");
                assert_eq!(ours.to_string(), reference.to_string());
            }
            (reference, ours) => panic!("bincode {reference:?}, in place {ours:?} on {bytes:?}"),
        }
        match (
            decode::<CallMsg>(bytes),
            decode_call_into(bytes, function, args),
        ) {
            (Ok(reference), Ok(())) => {
                let ours = CallMsg::new(function.clone(), args.clone());
                assert_eq!(encode(&ours), encode(&reference), "{bytes:?}");
            }
            (Err(reference), Err(ours)) => {
                assert_eq!(format!("{ours:?}"), format!("{reference:?}"), "{bytes:?}");
            }
            (reference, ours) => panic!("bincode {reference:?}, in place {ours:?} on {bytes:?}"),
        }
    }

    #[test]
    fn generated_bodies_decode_as_bincode_decodes_them_whatever_the_buffers_held() {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        // The buffers keep what the previous body left: every value replaces values of every
        // kind, lists longer and shorter.
        let (mut params, mut function, mut args) = (Vec::new(), String::new(), Vec::new());
        for _ in 0..4_000 {
            let event = EventMsg::new(rng.text(), rng.values());
            let bytes = encode(&event);
            agree(&bytes, &mut params, &mut function, &mut args);
            assert_eq!(encode(&CallMsg::new(event.name, event.params)), bytes);
        }
    }

    #[test]
    fn corrupt_and_truncated_bodies_are_refused_as_bincode_refuses_them() {
        let mut rng = Rng(0x2545_F491_4F6C_DD1D);
        let (mut params, mut function, mut args) = (Vec::new(), String::new(), Vec::new());
        for i in 0..30_000 {
            let valid = encode(&EventMsg::new(rng.text(), rng.values()));
            let bytes: Vec<u8> = match i % 5 {
                // Random bytes.
                0 => {
                    let n = rng.below(64) as usize;
                    (0..n).map(|_| rng.next() as u8).collect()
                }
                // A byte changed, often into a varint marker or a small variant index.
                1 | 2 => {
                    let mut b = valid;
                    if !b.is_empty() {
                        let at = rng.below(b.len() as u64) as usize;
                        b[at] = match rng.below(3) {
                            0 => 251 + rng.below(5) as u8,
                            1 => rng.below(6) as u8,
                            _ => rng.next() as u8,
                        };
                    }
                    b
                }
                // Cut short.
                3 => {
                    let mut b = valid;
                    let n = b.len();
                    b.truncate(rng.below(n as u64 + 1) as usize);
                    b
                }
                // Bytes left over.
                _ => {
                    let mut b = valid;
                    b.extend((0..1 + rng.below(3)).map(|_| rng.next() as u8));
                    b
                }
            };
            agree(&bytes, &mut params, &mut function, &mut args);
        }
    }

    #[test]
    fn every_cut_of_a_body_is_refused_as_bincode_refuses_it() {
        let event = EventMsg::new(
            "pong_0",
            vec![
                Value::Int(-300_000),
                Value::FloatList(vec![0.5; 6]),
                Value::Text("héllo".into()),
                Value::Bool(true),
                Value::Float(2.5),
            ],
        );
        let bytes = encode(&event);
        let (mut params, mut function, mut args) = (Vec::new(), String::new(), Vec::new());
        for n in 0..=bytes.len() {
            agree(&bytes[..n], &mut params, &mut function, &mut args);
        }
    }

    /// Lengths and integers as bincode also reads them: non-minimal varints, markers of larger
    /// types, and claims beyond the limit (a sequence's items, a text, many small values).
    #[test]
    fn crafted_bodies_meet_the_same_limits_and_markers() {
        let (mut params, mut function, mut args) = (Vec::new(), String::new(), Vec::new());
        let mut cases: Vec<Vec<u8>> = vec![
            // Name "ab" with a u16 length, no value (u64 length marker).
            vec![251, 2, 0, b'a', b'b', 253, 0, 0, 0, 0, 0, 0, 0, 0],
            // Value index as a u64 or u128 marker, and reserved.
            vec![0, 1, 253, 0, 0, 0, 0, 0, 0, 0, 0],
            vec![0, 1, 254, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
            vec![0, 1, 255],
            vec![0, 1, 5],
            // An int as a u128 marker, with and without 9 bytes after it.
            vec![0, 1, 0, 254, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
            vec![0, 1, 0, 254, 0],
            vec![0, 1, 0, 255],
            // A length as a u128 marker, with and without 9 bytes after it.
            vec![254, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0],
            vec![254, 0],
            // A bool of 2.
            vec![0, 1, 2, 2],
            // Invalid UTF-8 in the name, in a text.
            vec![2, 0xC3, 0x28, 0],
            vec![0, 1, 3, 1, 0xFF],
            // A text, a list of floats, a sequence of values claiming more than the limit.
            vec![253, 0, 0, 0, 0, 0, 0, 1, 0],
            vec![0, 1, 4, 253, 0, 0, 0, 0, 0, 0, 0, 0x20],
            vec![0, 1, 4, 253, 0, 0, 0, 0, 0, 0, 0, 0x01],
            vec![0, 253, 0, 0, 0x10, 0, 0, 0, 0, 0],
            vec![0, 253, 0, 0, 0, 0, 0, 0, 0, 0x10],
            // A list of floats ending inside its third float.
            vec![
                0, 1, 4, 3, 0, 0, 0, 0, 0, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10,
            ],
        ];
        // Many small values: under the limit on the wire, over it in bincode's claims (32
        // bytes claimed per item, then 12 kept for each int).
        for count in [30_000u32, 32_000, 32_767, 32_768, 40_000, 100_000] {
            let mut b = vec![0, 252];
            b.extend_from_slice(&count.to_le_bytes());
            for _ in 0..count {
                b.extend_from_slice(&[0, 0]);
            }
            cases.push(b);
        }
        // A body over the limit.
        cases.push(vec![0; MAX_BODY_LEN + 1]);
        for bytes in &cases {
            agree(bytes, &mut params, &mut function, &mut args);
        }
    }

    #[test]
    fn a_list_of_floats_in_the_same_position_keeps_its_buffer() {
        let call = CallMsg::new(
            "ping",
            vec![
                Value::Int(1),
                Value::FloatList(vec![1.0; 6]),
                Value::Text("x".into()),
            ],
        );
        let bytes = encode(&call);
        let (mut function, mut args) = (String::new(), Vec::new());
        decode_call_into(&bytes, &mut function, &mut args).unwrap();
        let (Value::FloatList(list), Value::Text(text)) = (&args[1], &args[2]) else {
            panic!("{args:?}");
        };
        let (list, text, names, all) = (
            list.as_ptr(),
            text.as_ptr(),
            function.as_ptr(),
            args.as_ptr(),
        );
        let next = encode(&CallMsg::new(
            "pong",
            vec![
                Value::Int(2),
                Value::FloatList(vec![2.0; 5]),
                Value::Text("y".into()),
            ],
        ));
        decode_call_into(&next, &mut function, &mut args).unwrap();
        assert_eq!(function, "pong");
        assert_eq!(args[1], Value::FloatList(vec![2.0; 5]));
        let (Value::FloatList(l), Value::Text(t)) = (&args[1], &args[2]) else {
            panic!("{args:?}");
        };
        assert_eq!(
            (l.as_ptr(), t.as_ptr(), function.as_ptr(), args.as_ptr()),
            (list, text, names, all)
        );
    }
}
