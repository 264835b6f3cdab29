//! Right-aligned text tables of the human-readable reports (`accomp tumble`, `accomp fit`,
//! `accomp stability`): each column's header and width are written once, so a header cannot
//! drift from its cells.

use std::fmt::{Display, Write as _};

/// The columns of a table: header and width (characters), in order.
pub(crate) struct Columns<const N: usize>(pub [(&'static str, usize); N]);

impl<const N: usize> Columns<N> {
    /// The header line: each header right-aligned in its column.
    pub fn header(&self) -> String {
        self.row(self.0.map(|(header, _)| header))
    }

    /// One row: each cell right-aligned in its column's width, the columns one space apart (a
    /// cell wider than its column is written whole, as `format!("{:>w$}")` does).
    pub fn row<T: Display>(&self, cells: [T; N]) -> String {
        let mut line = String::new();
        for (i, (&(_, width), cell)) in self.0.iter().zip(cells).enumerate() {
            if i > 0 {
                line.push(' ');
            }
            let _ = write!(line, "{cell:>width$}");
        }
        line
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_and_cells_share_their_column_widths() {
        let t = Columns([("a", 3), ("bb", 5)]);
        assert_eq!(t.header(), "  a    bb");
        assert_eq!(t.row([format!("{:.1}", 2.0), "x".into()]), "2.0     x");
        assert_eq!(t.row(["toolong", "y"]), "toolong     y");
    }
}
