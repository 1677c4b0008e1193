//! Range checks of settings that come from files, flags and checkpoints: a table of
//! `(name, value, low, high)` checked in one pass, the first value outside `low..=high` named
//! with its range. NaN is outside every range.

use std::fmt::Display;

/// A setting outside its range.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutOfRange<'a> {
    /// The setting's name.
    pub name: &'a str,
    /// Its value, as text.
    pub value: String,
    /// The range it must lie in, `LOW..=HIGH`.
    pub range: String,
}

impl Display for OutOfRange<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} = {} is outside {}",
            self.name, self.value, self.range
        )
    }
}

/// The first of `fields`, `(name, value, low, high)`, whose value lies outside `low..=high`.
pub fn first_outside<'a, T: PartialOrd + Display>(
    fields: impl IntoIterator<Item = (&'a str, T, T, T)>,
) -> Option<OutOfRange<'a>> {
    fields
        .into_iter()
        .find(|(_, value, low, high)| !(low..=high).contains(&value))
        .map(|(name, value, low, high)| OutOfRange {
            name,
            value: value.to_string(),
            range: format!("{low}..={high}"),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_value_outside_its_range_is_named_with_the_range() {
        let fields = [
            ("a", 1.0, 0.0, 2.0),
            ("b", 3.0, 0.0, 2.0),
            ("c", -1.0, 0.0, 2.0),
        ];
        let out = first_outside(fields).unwrap();
        assert_eq!(out.to_string(), "b = 3 is outside 0..=2");
        assert_eq!(
            first_outside([("n", f32::NAN, 0.0, 1.0)]).unwrap().value,
            "NaN"
        );
        assert_eq!(first_outside([("k", 5usize, 1, 5), ("j", 1, 1, 5)]), None);
    }
}
