//! Parameters declared once: the typed struct is the declaration.
//!
//! [`stage_params!`](crate::stage_params) writes a stage's parameter struct (serde) and, from the
//! same lines, the [`ParamSpec`] list the engine checks,
//! defaults and hashes (`pipeline::params::normalize`), which `shakeflow stages`, `--set` and the
//! JSON Schema read too. It sits below `io` and `pipeline` (it imports nothing of the crate), so an
//! equipment file's keys (`io::equipment`) are declared by the same struct the stages flatten. Each field says its type, and in brackets its default (a JSON value as
//! pipelines write it; none: the parameter is required), `unit`, `range` (inclusive) and, where
//! the type does not say it, `kind`; its doc comment is the description users see. A field marked
//! `#[flatten]` takes another declared struct's parameters in its place (the rocking unit shared by
//! two stages, the `mcap` switch). The structs do not refuse unknown keys themselves (serde's
//! `deny_unknown_fields` breaks under nested `flatten`): the engine refuses a key the declaration
//! lacks before any struct is read (`params::normalize`), and `params::check_typed` proves at
//! planning that the struct reads the normalised parameters back exactly. [`choice!`](crate::choice) declares a choice parameter's enum
//! with the names pipelines write.
//!
//! ```ignore
//! stage_params! {
//!     pub struct BaselineParams {
//!         /// polynomial order (3: the study's cubic; 1: linear detrend; 0: mean)
//!         pub order: usize [default = 3, range = (0.0, 9.0)],
//!     }
//! }
//! ```

use std::path::PathBuf;

use serde::de::DeserializeOwned;
use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamKind {
    Float,
    Int,
    Bool,
    Str,
    Choice(&'static [&'static str]),
    /// A list of names (e.g. columns); empty means "all".
    StrList,
    /// A list of numbers (e.g. scale factors), of exactly this many when given.
    FloatList(Option<usize>),
    /// A file path, relative to the pipeline file; the file's content is part of the cache key,
    /// so editing the file reruns the stage.
    Path,
}

impl ParamKind {
    pub fn describe(&self) -> String {
        match self {
            ParamKind::Float => "number".into(),
            ParamKind::Int => "integer".into(),
            ParamKind::Bool => "true|false".into(),
            ParamKind::Str => "text".into(),
            ParamKind::Choice(options) => options.join("|"),
            ParamKind::StrList => "list of names".into(),
            ParamKind::FloatList(Some(n)) => format!("list of {n} numbers"),
            ParamKind::FloatList(None) => "list of numbers".into(),
            ParamKind::Path => "file path (relative to the pipeline file)".into(),
        }
    }
}

#[derive(Debug, Clone, Copy)]
pub struct ParamSpec {
    pub name: &'static str,
    pub kind: ParamKind,
    /// JSON literal of the default; `None` makes the parameter required.
    pub default: Option<&'static str>,
    pub unit: &'static str,
    pub description: &'static str,
    /// Inclusive numeric bounds, checked on Float and Int.
    pub range: Option<(f64, f64)>,
}

/// A parameter struct written by [`stage_params!`](crate::stage_params): its parameters in the
/// order users see them.
pub trait Declared: DeserializeOwned + Serialize {
    fn declare(out: &mut Vec<ParamSpec>);

    /// The declaration as the engine takes it (`StageInfo::params`); built once per stage type.
    fn specs() -> &'static [ParamSpec] {
        let mut out = Vec::new();
        Self::declare(&mut out);
        Box::leak(out.into_boxed_slice())
    }
}

/// The kind of parameter a field's Rust type makes (an `Option` is its inner type, defaulting to
/// null).
pub trait ParamType {
    const KIND: ParamKind;
}

macro_rules! param_type {
    ($($ty:ty => $kind:expr),* $(,)?) => {
        $(impl ParamType for $ty {
            const KIND: ParamKind = $kind;
        })*
    };
}

param_type! {
    f64 => ParamKind::Float,
    usize => ParamKind::Int,
    bool => ParamKind::Bool,
    String => ParamKind::Str,
    Vec<String> => ParamKind::StrList,
    Vec<f64> => ParamKind::FloatList(None),
    PathBuf => ParamKind::Path,
}

impl<const N: usize> ParamType for [f64; N] {
    const KIND: ParamKind = ParamKind::FloatList(Some(N));
}

impl<T: ParamType> ParamType for Option<T> {
    const KIND: ParamKind = T::KIND;
}

/// Declares a stage's parameter struct and its [`Declared`] list (module docs).
#[macro_export]
macro_rules! stage_params {
    ($(#[$attr:meta])* $vis:vis struct $name:ident { $($body:tt)* }) => {
        $crate::stage_params!(@field [$(#[$attr])* $vis struct $name] [] [] $($body)*);
    };
    // A flattened struct: its parameters here.
    (@field $head:tt [$($fields:tt)*] [$($specs:tt)*]
        $(#[doc = $doc:literal])* #[flatten] $fvis:vis $field:ident : $ty:ty, $($rest:tt)*) => {
        $crate::stage_params!(@field $head
            [$($fields)* $(#[doc = $doc])* #[serde(flatten)] $fvis $field: $ty,]
            [$($specs)* (<$ty as $crate::declare::Declared>::declare)]
            $($rest)*);
    };
    // One parameter: its name is the field's, or its serde `rename`.
    (@field $head:tt [$($fields:tt)*] [$($specs:tt)*]
        $(#[doc = $doc:literal])* $(#[serde(rename = $rename:literal)])?
        $fvis:vis $field:ident : $ty:ty [$($key:ident = $value:expr),* $(,)?], $($rest:tt)*) => {
        $crate::stage_params!(@field $head
            [$($fields)* $(#[doc = $doc])* $(#[serde(rename = $rename)])? $fvis $field: $ty,]
            [$($specs)* (|out: &mut Vec<$crate::declare::ParamSpec>| out.push({
                #[allow(unused_mut)]
                let mut spec = $crate::declare::ParamSpec {
                    name: $crate::stage_params!(@name $field $($rename)?),
                    kind: <$ty as $crate::declare::ParamType>::KIND,
                    default: None,
                    unit: "",
                    description: concat!($($doc),*).trim_start(),
                    range: None,
                };
                $($crate::stage_params!(@set spec $key $value);)*
                spec
            }))]
            $($rest)*);
    };
    (@field [$(#[$attr:meta])* $vis:vis struct $name:ident] [$($fields:tt)*] [$($specs:tt)*]) => {
        $(#[$attr])*
        #[derive(Debug, serde::Deserialize, serde::Serialize)]
        $vis struct $name { $($fields)* }

        impl $crate::declare::Declared for $name {
            #[allow(unused_variables)]
            fn declare(out: &mut Vec<$crate::declare::ParamSpec>) {
                $($specs(out);)*
            }
        }
    };
    (@name $field:ident) => { stringify!($field) };
    (@name $field:ident $rename:literal) => { $rename };
    (@set $spec:ident default $value:expr) => { $spec.default = Some(stringify!($value)) };
    (@set $spec:ident unit $value:expr) => { $spec.unit = $value };
    (@set $spec:ident range $value:expr) => { $spec.range = Some($value) };
    (@set $spec:ident kind $value:expr) => { $spec.kind = $value };
}

/// Declares a choice parameter's enum: each variant with the name pipelines write.
#[macro_export]
macro_rules! choice {
    ($(#[$attr:meta])* $vis:vis enum $name:ident { $($(#[doc = $doc:literal])* $variant:ident = $text:literal),* $(,)? }) => {
        $(#[$attr])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
        $vis enum $name {
            $($(#[doc = $doc])* #[serde(rename = $text)] $variant),*
        }

        impl $crate::declare::ParamType for $name {
            const KIND: $crate::declare::ParamKind = $crate::declare::ParamKind::Choice(&[$($text),*]);
        }
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::params::{check_typed, normalize};
    use crate::stages::Mcap;
    use serde_json::json;

    crate::choice! {
        enum Zero { FirstFrame = "first_frame", Upright = "upright" }
    }

    crate::stage_params! {
        struct Inner {
            /// a trapezoid's
            /// base
            #[serde(rename = "B1_m")]
            b1_m: Option<f64> [default = null, unit = "m", range = (1e-6, 1e3)],
        }
    }

    crate::stage_params! {
        struct Middle {
            /// a middle value
            x: f64 [default = 1.0],
            #[flatten]
            inner: Inner,
        }
    }

    crate::stage_params! {
        struct Example {
            /// polynomial order
            order: usize [default = 3, range = (0.0, 9.0)],
            /// channels
            columns: Vec<String> [],
            theta_zero: Zero [default = "upright"],
            steer0_deg: Option<[f64; 4]> [default = null, unit = "deg"],
            preset: Option<String> [default = null, kind = ParamKind::Choice(&["PS2", "PB1"])],
            scale: f64 [default = -1.5],
            #[flatten]
            middle: Middle,
            #[flatten]
            mcap: Mcap,
        }
    }

    #[test]
    fn a_struct_declares_its_parameters_in_order_with_their_docs_defaults_and_kinds() {
        let specs = Example::specs();
        let names: Vec<&str> = specs.iter().map(|s| s.name).collect();
        assert_eq!(names, ["order", "columns", "theta_zero", "steer0_deg", "preset", "scale", "x", "B1_m", "mcap"]);
        let by = |n: &str| *specs.iter().find(|s| s.name == n).unwrap();
        assert_eq!(
            (by("order").kind, by("order").default, by("order").range, by("order").description),
            (ParamKind::Int, Some("3"), Some((0.0, 9.0)), "polynomial order")
        );
        assert_eq!((by("columns").kind, by("columns").default), (ParamKind::StrList, None));
        assert_eq!(by("theta_zero").kind, ParamKind::Choice(&["first_frame", "upright"]));
        assert_eq!(by("theta_zero").default, Some("\"upright\""));
        assert_eq!((by("steer0_deg").kind, by("steer0_deg").unit), (ParamKind::FloatList(Some(4)), "deg"));
        assert_eq!(by("preset").kind, ParamKind::Choice(&["PS2", "PB1"]));
        assert_eq!(by("scale").default, Some("-1.5"));
        assert_eq!(by("B1_m").description, "a trapezoid's base");
        assert_eq!(by("mcap").default, Some("false"));
        // What the engine normalises reads back into the struct exactly, through nested flattening.
        let given = [("columns", json!("a")), ("theta_zero", json!("first_frame")), ("B1_m", json!(0.4))];
        let params = normalize(specs, "example", given).unwrap();
        check_typed::<Example>(&params).unwrap();
        let typed: Example = crate::pipeline::params::typed(&params).unwrap();
        assert_eq!((typed.order, typed.theta_zero, typed.scale), (3, Zero::FirstFrame, -1.5));
        assert_eq!((typed.middle.x, typed.middle.inner.b1_m), (1.0, Some(0.4)));
        // A key the declaration lacks is the engine's to refuse, before the struct is read.
        assert!(normalize(specs, "example", [("B_1m", json!(1))]).unwrap_err().hint.contains("did you mean `B1_m`"));
        assert!(!typed.mcap.mcap && typed.steer0_deg.is_none() && typed.preset.is_none() && typed.columns == ["a"]);
    }
}
