//! The command-line names of the enums a user picks from ([`Method`], [`Preset`], [`Ablation`],
//! [`Backend`], [`FinetuneLoss`], [`LossScale`], [`Sampling`]):
//! each enum lists its values in `ALL` and spells them in `name()`, the only place the names
//! are written; `named!` derives parsing, printing and (with the `clap` feature, which the
//! binary turns on) `clap::ValueEnum` from those two, so that every command lists the same
//! values in its help and its errors.
//!
//! [`Method`]: crate::method::Method
//! [`Preset`]: crate::model::Preset
//! [`Ablation`]: crate::method::Ablation
//! [`Backend`]: crate::Backend
//! [`FinetuneLoss`]: crate::train::schedule::FinetuneLoss
//! [`LossScale`]: crate::loss::LossScale
//! [`Sampling`]: crate::train::patches::Sampling

/// A name that is none of an enum's values.
#[derive(Debug, thiserror::Error)]
#[error("unknown {what} `{name}` (expected one of {})", known.join(", "))]
pub struct UnknownName {
    pub what: &'static str,
    pub name: String,
    pub known: Vec<&'static str>,
}

/// `FromStr`, `Display` and `clap::ValueEnum` of an enum with `ALL` and `name()`; `$what` names
/// the kind of value in errors.
macro_rules! named {
    ($t:ty, $what:literal) => {
        impl std::str::FromStr for $t {
            type Err = $crate::names::UnknownName;
            fn from_str(s: &str) -> Result<Self, Self::Err> {
                <$t>::ALL.into_iter().find(|v| v.name() == s).ok_or_else(|| $crate::names::UnknownName {
                    what: $what,
                    name: s.to_string(),
                    known: <$t>::ALL.iter().map(|v| v.name()).collect(),
                })
            }
        }

        impl std::fmt::Display for $t {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        #[cfg(feature = "clap")]
        impl clap::ValueEnum for $t {
            fn value_variants<'a>() -> &'a [Self] {
                &<$t>::ALL
            }
            fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
                Some(clap::builder::PossibleValue::new(self.name()))
            }
        }
    };
}
pub(crate) use named;
