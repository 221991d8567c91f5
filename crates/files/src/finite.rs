//! The guard of [`crate::save_json`]: serde_json writes a NaN or an infinity as `null`,
//! which the next read refuses (setting the whole file aside), so a value holding one is
//! found here, with where it sits, and never written.

use std::fmt;

use serde::Serialize;
use serde::ser::{self, SerializeMap, SerializeSeq, SerializeStruct, SerializeStructVariant};
use serde::ser::{SerializeTuple, SerializeTupleStruct, SerializeTupleVariant};

/// Where the first number of `value` that is not finite sits and what it is
/// (`live.lights[3].intensity is NaN`); `None` when every number is finite.
pub fn first_non_finite<T: Serialize + ?Sized>(value: &T) -> Option<String> {
    match value.serialize(&mut Walk::default()) {
        Err(Stop::NonFinite(what)) => Some(what),
        Ok(()) | Err(Stop::Other) => None,
    }
}

/// Why the walk stopped: a number that is not finite, or the value's own serialisation
/// error (which the real write reports).
#[derive(Debug)]
enum Stop {
    NonFinite(String),
    Other,
}

impl fmt::Display for Stop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Stop::NonFinite(what) => f.write_str(what),
            Stop::Other => f.write_str("the value does not serialise"),
        }
    }
}

impl std::error::Error for Stop {}

impl ser::Error for Stop {
    fn custom<T: fmt::Display>(_: T) -> Stop {
        Stop::Other
    }
}

/// A serializer that writes nothing: it only follows the path (`.field`, `[index]`,
/// `[key]`) to each number.
#[derive(Default)]
struct Walk {
    path: Vec<String>,
}

impl Walk {
    fn number(&self, v: f64) -> Result<(), Stop> {
        if v.is_finite() {
            return Ok(());
        }
        let at = self.path.concat();
        let at = match at.trim_start_matches('.') {
            "" => "the value",
            at => at,
        };
        Err(Stop::NonFinite(format!("{at} is {v}")))
    }

    fn inside<T: Serialize + ?Sized>(&mut self, segment: String, value: &T) -> Result<(), Stop> {
        self.path.push(segment);
        let r = value.serialize(&mut *self);
        self.path.pop();
        r
    }
}

/// The parts of a sequence, tuple, map or struct, walked in order.
struct Parts<'a> {
    walk: &'a mut Walk,
    index: usize,
    key: String,
}

impl Parts<'_> {
    fn item<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        let i = self.index;
        self.index += 1;
        self.walk.inside(format!("[{i}]"), value)
    }
}

macro_rules! nothing_to_check {
    ($($name:ident: $t:ty),* $(,)?) => {
        $(fn $name(self, _: $t) -> Result<(), Stop> {
            Ok(())
        })*
    };
}

impl<'a> ser::Serializer for &'a mut Walk {
    type Ok = ();
    type Error = Stop;
    type SerializeSeq = Parts<'a>;
    type SerializeTuple = Parts<'a>;
    type SerializeTupleStruct = Parts<'a>;
    type SerializeTupleVariant = Parts<'a>;
    type SerializeMap = Parts<'a>;
    type SerializeStruct = Parts<'a>;
    type SerializeStructVariant = Parts<'a>;

    nothing_to_check!(
        serialize_bool: bool,
        serialize_i8: i8,
        serialize_i16: i16,
        serialize_i32: i32,
        serialize_i64: i64,
        serialize_i128: i128,
        serialize_u8: u8,
        serialize_u16: u16,
        serialize_u32: u32,
        serialize_u64: u64,
        serialize_u128: u128,
        serialize_char: char,
        serialize_str: &str,
        serialize_bytes: &[u8],
        serialize_unit_struct: &'static str,
    );

    fn serialize_f32(self, v: f32) -> Result<(), Stop> {
        self.number(f64::from(v))
    }

    fn serialize_f64(self, v: f64) -> Result<(), Stop> {
        self.number(v)
    }

    fn serialize_none(self) -> Result<(), Stop> {
        Ok(())
    }

    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<(), Stop> {
        value.serialize(self)
    }

    fn serialize_unit(self) -> Result<(), Stop> {
        Ok(())
    }

    fn serialize_unit_variant(self, _: &'static str, _: u32, _: &'static str) -> Result<(), Stop> {
        Ok(())
    }

    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        value: &T,
    ) -> Result<(), Stop> {
        value.serialize(self)
    }

    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<(), Stop> {
        self.inside(format!(".{variant}"), value)
    }

    fn serialize_seq(self, _: Option<usize>) -> Result<Parts<'a>, Stop> {
        Ok(Parts {
            walk: self,
            index: 0,
            key: String::new(),
        })
    }

    fn serialize_tuple(self, len: usize) -> Result<Parts<'a>, Stop> {
        self.serialize_seq(Some(len))
    }

    fn serialize_tuple_struct(self, _: &'static str, len: usize) -> Result<Parts<'a>, Stop> {
        self.serialize_seq(Some(len))
    }

    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        len: usize,
    ) -> Result<Parts<'a>, Stop> {
        self.serialize_seq(Some(len))
    }

    fn serialize_map(self, len: Option<usize>) -> Result<Parts<'a>, Stop> {
        self.serialize_seq(len)
    }

    fn serialize_struct(self, _: &'static str, len: usize) -> Result<Parts<'a>, Stop> {
        self.serialize_seq(Some(len))
    }

    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        len: usize,
    ) -> Result<Parts<'a>, Stop> {
        self.serialize_seq(Some(len))
    }
}

impl SerializeSeq for Parts<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.item(value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl SerializeTuple for Parts<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.item(value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl SerializeTupleStruct for Parts<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.item(value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl SerializeTupleVariant for Parts<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        self.item(value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl SerializeMap for Parts<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Result<(), Stop> {
        // The key as JSON writes it, for the path (`looks[3]`).
        self.key = serde_json::to_string(key)
            .map(|k| k.trim_matches('"').to_string())
            .unwrap_or_default();
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), Stop> {
        let key = std::mem::take(&mut self.key);
        self.walk.inside(format!("[{key}]"), value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl SerializeStruct for Parts<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        name: &'static str,
        value: &T,
    ) -> Result<(), Stop> {
        self.walk.inside(format!(".{name}"), value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

impl SerializeStructVariant for Parts<'_> {
    type Ok = ();
    type Error = Stop;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        name: &'static str,
        value: &T,
    ) -> Result<(), Stop> {
        self.walk.inside(format!(".{name}"), value)
    }
    fn end(self) -> Result<(), Stop> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    #[derive(Serialize)]
    struct Light {
        channel: u32,
        intensity: f32,
        color: Option<[f32; 3]>,
    }

    #[derive(Serialize)]
    struct File {
        master: f64,
        looks: BTreeMap<u32, Vec<Light>>,
    }

    fn file(intensity: f32, blue: f32, master: f64) -> File {
        let light = |channel, intensity, color| Light {
            channel,
            intensity,
            color,
        };
        File {
            master,
            looks: BTreeMap::from([(
                7,
                vec![
                    light(1, 0.5, None),
                    light(2, intensity, Some([1.0, 0.5, blue])),
                ],
            )]),
        }
    }

    #[test]
    fn the_first_number_that_is_not_finite_is_named_by_its_path() {
        assert_eq!(first_non_finite(&file(0.25, 0.0, 1.0)), None);
        assert_eq!(
            first_non_finite(&file(f32::NAN, 0.0, 1.0)).as_deref(),
            Some("looks[7][1].intensity is NaN")
        );
        assert_eq!(
            first_non_finite(&file(0.25, f32::INFINITY, 1.0)).as_deref(),
            Some("looks[7][1].color[2] is inf")
        );
        assert_eq!(
            first_non_finite(&file(f32::NAN, 0.0, f64::NEG_INFINITY)).as_deref(),
            Some("master is -inf")
        );
        assert_eq!(
            first_non_finite(&f32::NAN).as_deref(),
            Some("the value is NaN")
        );
    }
}
