//! A minimal XML writer for OpenDRIVE documents: indented elements with
//! attributes, and fixed-decimal number formatting so the output is
//! byte-identical on every run and platform.
//!
//! Attribute values are written verbatim. The generator only ever writes
//! numbers and fixed ASCII names, which [`Xml::open`] checks in debug builds,
//! so nothing needs escaping.

use std::fmt::Write;

/// Decimals for positions, lengths and widths: a micrometre.
const LENGTH_DECIMALS: usize = 6;
/// Decimals for headings and curvatures.
const ANGLE_DECIMALS: usize = 9;
/// Decimals for `paramPoly3` coefficients: a nanometre. Fewer than
/// [`COEFF_DECIMALS`] because they come through `sin` and `cos`, whose last
/// bit may differ between platforms' maths libraries; a rounding boundary is
/// then a thousand times less likely to fall between two platforms' values.
const CURVE_DECIMALS: usize = 9;
/// Decimals for profile polynomial coefficients, whose cubic terms can be
/// tiny. They come from plain arithmetic.
const COEFF_DECIMALS: usize = 12;

/// `value` with `decimals` fixed decimals, never as `-0.000`.
fn fixed(value: f64, decimals: usize) -> String {
    assert!(value.is_finite(), "non-finite number in a town: {value}");
    let text = format!("{value:.decimals$}");
    if text.starts_with('-') && text[1..].chars().all(|c| c == '0' || c == '.') {
        text[1..].to_string()
    } else {
        text
    }
}

/// A length or coordinate, in metres.
pub fn len(value: f64) -> String {
    fixed(value, LENGTH_DECIMALS)
}

/// An angle in radians, or a curvature in 1/m.
pub fn ang(value: f64) -> String {
    fixed(value, ANGLE_DECIMALS)
}

/// A `paramPoly3` coefficient, in metres.
pub fn curve(value: f64) -> String {
    fixed(value, CURVE_DECIMALS)
}

/// A profile polynomial coefficient (elevation, width, lane offset).
pub fn coef(value: f64) -> String {
    fixed(value, COEFF_DECIMALS)
}

/// An indented XML document under construction.
pub struct Xml {
    out: String,
    depth: usize,
}

impl Xml {
    /// A document with its `<?xml?>` declaration.
    pub fn new() -> Self {
        Self {
            out: String::from("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"),
            depth: 0,
        }
    }

    fn start_tag(&mut self, tag: &str, attrs: &[(&str, String)]) {
        self.indent();
        self.out.push('<');
        self.out.push_str(tag);
        for (name, value) in attrs {
            debug_assert!(
                !value.contains(['<', '>', '&', '"']),
                "attribute {name}={value:?} would need escaping"
            );
            write!(self.out, " {name}=\"{value}\"").expect("writing to a String");
        }
    }

    fn indent(&mut self) {
        for _ in 0..self.depth {
            self.out.push_str("  ");
        }
    }

    /// Open `<tag attrs>`; children follow until [`Xml::close`].
    pub fn open(&mut self, tag: &str, attrs: &[(&str, String)]) {
        self.start_tag(tag, attrs);
        self.out.push_str(">\n");
        self.depth += 1;
    }

    /// Write an empty element `<tag attrs/>`.
    pub fn leaf(&mut self, tag: &str, attrs: &[(&str, String)]) {
        self.start_tag(tag, attrs);
        self.out.push_str("/>\n");
    }

    /// Write `<tag><![CDATA[text]]></tag>`.
    pub fn cdata(&mut self, tag: &str, text: &str) {
        debug_assert!(!text.contains("]]>"));
        self.indent();
        writeln!(self.out, "<{tag}><![CDATA[{text}]]></{tag}>").expect("writing to a String");
    }

    /// Close the element `tag` opened last.
    pub fn close(&mut self, tag: &str) {
        self.depth -= 1;
        self.indent();
        writeln!(self.out, "</{tag}>").expect("writing to a String");
    }

    /// The finished document.
    pub fn finish(self) -> String {
        debug_assert_eq!(self.depth, 0, "unclosed elements");
        self.out
    }
}

/// An attribute list entry from anything printable, such as an id or a name.
pub fn attr(name: &'static str, value: impl ToString) -> (&'static str, String) {
    (name, value.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_fixed_and_never_negative_zero() {
        assert_eq!(len(1.0), "1.000000");
        assert_eq!(len(-1e-9), "0.000000");
        assert_eq!(ang(-0.0), "0.000000000");
        assert_eq!(coef(-2.5e-5), "-0.000025000000");
    }

    #[test]
    fn elements_nest_with_indentation() {
        let mut xml = Xml::new();
        xml.open("a", &[attr("id", 1)]);
        xml.leaf("b", &[("x", len(0.5))]);
        xml.close("a");
        assert_eq!(
            xml.finish(),
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<a id=\"1\">\n  <b x=\"0.500000\"/>\n</a>\n"
        );
    }
}
