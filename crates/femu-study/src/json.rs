//! Reading femu's JSON results back into their typed structs.
//!
//! JSON has no NaN or infinity: serde_json writes a non-finite number as `null` (a parameter
//! the data cannot see has an infinite standard deviation; a failed Newton trial a NaN residual).
//! [`from_str`] reads every `null` that stands where a number is expected as NaN, so that a
//! summary always reads back into the struct that wrote it; a `null` where an `Option` is
//! expected stays `None`. (Inside an untagged enum serde buffers the value before it knows the
//! type, and a `null` there is read as a unit: the summaries keep non-finite numbers out of
//! their untagged enums.)

use serde::de::{
    self, DeserializeSeed, Deserializer, IntoDeserializer, MapAccess, SeqAccess, Visitor,
};
use serde_json::Value;

/// `T` from JSON text, with `null` numbers read as NaN.
pub fn from_str<T: de::DeserializeOwned>(text: &str) -> Result<T, serde_json::Error> {
    let value: Value = serde_json::from_str(text)?;
    T::deserialize(NanAware(value))
}

/// A JSON value whose `null`s read as NaN where a float is expected.
struct NanAware(Value);

macro_rules! forward_to_value {
    ($($method:ident)*) => {$(
        fn $method<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
            self.deserialize_any(visitor)
        }
    )*};
}

impl<'de> Deserializer<'de> for NanAware {
    type Error = serde_json::Error;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        match self.0 {
            Value::Array(items) => visitor.visit_seq(Items(items.into_iter())),
            Value::Object(map) => visitor.visit_map(Entries {
                entries: map.into_iter(),
                value: None,
            }),
            other => other.deserialize_any(visitor),
        }
    }

    fn deserialize_f64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        match self.0 {
            Value::Null => visitor.visit_f64(f64::NAN),
            other => other.deserialize_f64(visitor),
        }
    }

    fn deserialize_f32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        match self.0 {
            Value::Null => visitor.visit_f32(f32::NAN),
            other => other.deserialize_f32(visitor),
        }
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, Self::Error> {
        match self.0 {
            Value::Null => visitor.visit_none(),
            other => visitor.visit_some(NanAware(other)),
        }
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        name: &'static str,
        variants: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        self.0.deserialize_enum(name, variants, visitor)
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        name: &'static str,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        self.0.deserialize_unit_struct(name, visitor)
    }

    fn deserialize_tuple<V: Visitor<'de>>(
        self,
        _len: usize,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        self.deserialize_any(visitor)
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _len: usize,
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        self.deserialize_any(visitor)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, Self::Error> {
        self.deserialize_any(visitor)
    }

    forward_to_value! {
        deserialize_bool deserialize_i8 deserialize_i16 deserialize_i32 deserialize_i64
        deserialize_i128 deserialize_u8 deserialize_u16 deserialize_u32 deserialize_u64
        deserialize_u128 deserialize_char deserialize_str deserialize_string deserialize_bytes
        deserialize_byte_buf deserialize_unit deserialize_seq deserialize_map
        deserialize_identifier deserialize_ignored_any
    }
}

impl<'de> IntoDeserializer<'de, serde_json::Error> for NanAware {
    type Deserializer = NanAware;
    fn into_deserializer(self) -> NanAware {
        self
    }
}

struct Items(std::vec::IntoIter<Value>);

impl<'de> SeqAccess<'de> for Items {
    type Error = serde_json::Error;
    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, Self::Error> {
        self.0
            .next()
            .map(|v| seed.deserialize(NanAware(v)))
            .transpose()
    }
}

struct Entries {
    entries: serde_json::map::IntoIter,
    value: Option<Value>,
}

impl<'de> MapAccess<'de> for Entries {
    type Error = serde_json::Error;
    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, Self::Error> {
        match self.entries.next() {
            Some((k, v)) => {
                self.value = Some(v);
                seed.deserialize(Value::String(k)).map(Some)
            }
            None => Ok(None),
        }
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(
        &mut self,
        seed: V,
    ) -> Result<V::Value, Self::Error> {
        let v = self
            .value
            .take()
            .ok_or_else(|| de::Error::custom("a map value without its key"))?;
        seed.deserialize(NanAware(v))
    }
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, Serialize, Deserialize)]
    struct Inner {
        sd: f64,
        band: [f64; 2],
        note: Option<String>,
        extra: Option<f64>,
    }

    #[derive(Debug, Serialize, Deserialize)]
    #[serde(untagged)]
    enum Either {
        A { a: f64 },
        B { b: usize },
    }

    #[derive(Debug, Serialize, Deserialize)]
    struct Outer {
        list: Vec<Inner>,
        pairs: Vec<(String, f64)>,
        grid: Vec<Vec<f64>>,
        either: Either,
        tuple: (usize, usize),
    }

    /// Non-finite numbers written as null read back as NaN, anywhere; Options stay None.
    #[test]
    fn nulls_read_back_as_nan_and_options_as_none() {
        let value = Outer {
            list: vec![Inner {
                sd: f64::INFINITY,
                band: [0.0, f64::NAN],
                note: None,
                extra: None,
            }],
            pairs: vec![("x".into(), f64::NAN), ("y".into(), 2.5)],
            grid: vec![vec![1.0, f64::NEG_INFINITY]],
            either: Either::A { a: 0.5 },
            tuple: (3, 4),
        };
        let text = serde_json::to_string_pretty(&value).unwrap();
        assert!(
            serde_json::from_str::<Outer>(&text).is_err(),
            "plain serde_json refuses"
        );
        let back: Outer = super::from_str(&text).unwrap();
        assert!(back.list[0].sd.is_nan() && back.list[0].band[1].is_nan());
        assert_eq!(back.list[0].band[0], 0.0);
        assert!(back.list[0].note.is_none() && back.list[0].extra.is_none());
        assert!(back.pairs[0].1.is_nan() && back.pairs[1].1 == 2.5);
        assert!(back.grid[0][1].is_nan());
        assert!(matches!(back.either, Either::A { a } if a == 0.5));
        assert_eq!(back.tuple, (3, 4));
    }
}
