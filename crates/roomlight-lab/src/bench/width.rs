//! Every table a bench prints fits a terminal of 120 columns (issue 22): a cell too long for
//! its column wraps inside it instead of the table running off the screen. A bench's table
//! function calls [`fit`] on the table it built, rows and all; a table written into a markdown
//! file calls [`markdown`] instead (one line per row, as markdown needs; its renderer reflows
//! it). A table with more columns than 120 can show side by side is printed with [`split`]:
//! several tables one under another, each repeating the columns that say what a row is.

use comfy_table::{ColumnConstraint, ContentArrangement, Table, Width, presets::ASCII_MARKDOWN};

/// The widest line of a printed table, in characters.
pub const MAX_COLUMNS: u16 = 120;

/// Makes `table` wrap its cells so that none of its lines is longer than [`MAX_COLUMNS`]
/// characters, whether or not the output is a terminal. When the rows' cells fit side by side
/// at their own width, only the headers wrap (between words): a case name or a figure is never
/// cut. Call it once the rows are in.
pub fn fit(table: &mut Table) -> &mut Table {
    table
        .set_content_arrangement(ContentArrangement::Dynamic)
        .set_width(MAX_COLUMNS);
    let widths = cell_widths(table);
    if framed(&widths) <= usize::from(MAX_COLUMNS) {
        for (column, w) in table.column_iter_mut().zip(widths) {
            let w = u16::try_from(w).unwrap_or(MAX_COLUMNS);
            column.set_constraint(ColumnConstraint::LowerBoundary(Width::Fixed(w)));
        }
    }
    table
}

/// `table` as printed within [`MAX_COLUMNS`]: whole ([`fit`]) when its cells can stand side by
/// side, else as several tables one under another, each with the first `keys` columns (what
/// a row is, e.g. case and rule) and as many of the others as fit, every cell whole.
pub fn split(table: &mut Table, keys: usize) -> String {
    let widths = cell_widths(table);
    if framed(&widths) <= usize::from(MAX_COLUMNS) || widths.len() <= keys {
        return fit(table).to_string();
    }
    let preset = table.current_style_as_preset();
    let header: Vec<String> = table
        .header()
        .map(|h| h.cell_iter().map(|c| c.content()).collect())
        .unwrap_or_default();
    let rows: Vec<Vec<String>> = table
        .row_iter()
        .map(|r| r.cell_iter().map(|c| c.content()).collect())
        .collect();
    // Columns in groups, each as many as fit beside the keys.
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for k in keys..widths.len() {
        let fits = groups.last().is_some_and(|g| {
            let w: Vec<usize> = (0..keys)
                .chain(g.iter().copied())
                .chain([k])
                .map(|c| widths[c])
                .collect();
            framed(&w) <= usize::from(MAX_COLUMNS)
        });
        match groups.last_mut() {
            Some(g) if fits => g.push(k),
            _ => groups.push(vec![k]),
        }
    }
    let pick = |cells: &[String], columns: &[usize]| -> Vec<String> {
        columns
            .iter()
            .map(|&c| cells.get(c).cloned().unwrap_or_default())
            .collect()
    };
    groups
        .iter()
        .map(|g| {
            let columns: Vec<usize> = (0..keys).chain(g.iter().copied()).collect();
            let mut part = Table::new();
            part.load_preset(&preset);
            if !header.is_empty() {
                part.set_header(pick(&header, &columns));
            }
            for row in &rows {
                part.add_row(pick(row, &columns));
            }
            fit(&mut part).to_string()
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// The widest line of each column's cells, headers left out, plus its padding of 2.
fn cell_widths(table: &Table) -> Vec<usize> {
    let mut widths: Vec<usize> = Vec::new();
    for row in table.row_iter() {
        for (k, cell) in row.cell_iter().enumerate() {
            let wide = cell
                .content()
                .lines()
                .map(|l| l.chars().count())
                .max()
                .unwrap_or(0)
                + 2;
            match widths.get_mut(k) {
                Some(w) => *w = (*w).max(wide),
                None => widths.push(wide),
            }
        }
    }
    widths
}

/// The width of a table of columns this wide: a border left of each and one at the end.
fn framed(widths: &[usize]) -> usize {
    widths.iter().sum::<usize>() + widths.len() + 1
}

/// Makes `table` a markdown table: the ASCII markdown preset, one line per row, as wide as its
/// cells (markdown cannot wrap a row over lines).
pub fn markdown(table: &mut Table) -> &mut Table {
    table
        .load_preset(ASCII_MARKDOWN)
        .set_content_arrangement(ContentArrangement::Disabled)
}

#[cfg(test)]
mod tests {
    use super::*;
    use comfy_table::presets::UTF8_FULL_CONDENSED;

    /// The longest line of `table` as printed, in characters (not bytes: `─`, `µ`, `Δ`, `…`).
    fn widest(table: &Table) -> usize {
        table
            .to_string()
            .lines()
            .map(|l| l.chars().count())
            .max()
            .unwrap_or(0)
    }

    /// A table as wide as the room bench's with every column it may gain: fourteen columns of
    /// long headers and cells with ranges.
    fn wide() -> Table {
        let header: Vec<String> = [
            "case",
            "rule",
            "to 1%",
            "to 0.1%",
            "final excess (range)",
            "mean ΔE00 (range)",
            "max ΔE00",
            "compute µs/round",
            "message ms/round",
            "capture ms",
            "bytes/round",
            "diverged",
            "wall-clock s to 1%",
            "reproducible",
        ]
        .map(String::from)
        .to_vec();
        let row: Vec<String> = [
            "lab/warm-white-stale-errors",
            "momentum+model rounds",
            "12 (10…> 30)",
            "> 30",
            "1.2e-4 (8.1e-5…3.3e-3)",
            "1.23 (1.10…1.57)",
            "4.56",
            "1234.5",
            "12.34",
            "1200",
            "123456",
            "false",
            "12.3 (11.0…14.2)",
            "yes (seed 1, 3 repeats)",
        ]
        .map(String::from)
        .to_vec();
        let mut t = Table::new();
        t.load_preset(UTF8_FULL_CONDENSED).set_header(header);
        t.add_row(row.clone()).add_row(row);
        t
    }

    #[test]
    fn a_wide_table_is_wider_than_the_limit_until_fitted() {
        let mut t = wide();
        assert!(widest(&t) > usize::from(MAX_COLUMNS), "{t}");
        fit(&mut t);
        assert!(widest(&t) <= usize::from(MAX_COLUMNS), "{t}");
        // Every row is still there, wrapped over lines.
        assert!(t.to_string().lines().count() > 6, "{t}");
    }

    /// The core bench's table: nine columns whose headers are wider than their figures.
    #[test]
    fn only_the_headers_wrap_when_the_figures_fit() {
        let mut t = Table::new();
        t.load_preset(UTF8_FULL_CONDENSED).set_header([
            "case",
            "rule",
            "captures to 1%",
            "captures to 0.1%",
            "final excess",
            "mean ΔE00",
            "µs / node update",
            "captures run",
            "model rounds",
        ]);
        for case in ["synthetic-100", "reflective-100"] {
            for rule in ["global-oracle", "model-20"] {
                t.add_row([
                    case,
                    rule,
                    "18",
                    "31",
                    "-2.66e-16",
                    "2.357",
                    "1.934",
                    "91",
                    "20",
                ]);
            }
        }
        assert!(widest(&t) > usize::from(MAX_COLUMNS), "{t}");
        fit(&mut t);
        assert!(widest(&t) <= usize::from(MAX_COLUMNS), "{t}");
        let printed = t.to_string();
        for whole in [
            "synthetic-100",
            "reflective-100",
            "global-oracle",
            "-2.66e-16",
        ] {
            assert!(printed.contains(whole), "{whole} cut in\n{printed}");
        }
        // Header (wrapped), its rule, four rows, top and bottom.
        assert_eq!(printed.lines().count(), 2 + 1 + 4 + 2, "{printed}");
    }

    /// The room bench's many columns: split into tables that repeat case and rule.
    #[test]
    fn a_table_too_wide_for_its_cells_is_split_with_its_keys_repeated() {
        let mut t = wide();
        let printed = split(&mut t, 2);
        let fits = |l: &str| l.chars().count() <= usize::from(MAX_COLUMNS);
        assert!(printed.lines().all(fits), "{printed}");
        // Every cell whole, the keys in every part.
        for whole in ["(8.1e-5…3.3e-3)", "123456", "(11.0…14.2)", "reproducible"] {
            assert!(printed.contains(whole), "{whole} in\n{printed}");
        }
        let parts = printed.lines().filter(|l| l.starts_with('┌')).count();
        assert!(parts >= 2, "{printed}");
        let key = "lab/warm-white-stale-errors";
        assert_eq!(printed.matches(key).count(), 2 * parts, "{printed}");
        // A table that fits is printed whole.
        let mut narrow = Table::new();
        narrow.set_header(["case", "rule"]).add_row(["a", "b"]);
        let whole = split(&mut narrow, 2);
        assert_eq!(whole, fit(&mut narrow).to_string());
    }

    #[test]
    fn a_narrow_table_is_left_as_it_is() {
        let mut t = Table::new();
        t.load_preset(UTF8_FULL_CONDENSED)
            .set_header(["nodes", "median ms"])
            .add_row(["10", "0.123"]);
        let before = t.to_string();
        fit(&mut t);
        assert_eq!(t.to_string(), before);
    }

    #[test]
    fn a_markdown_table_keeps_one_line_per_row() {
        let mut t = wide();
        fit(&mut t);
        markdown(&mut t);
        let printed = t.to_string();
        // Header, separator and the two rows.
        assert_eq!(printed.lines().count(), 4, "{printed}");
        assert!(printed.lines().all(|l| l.starts_with('|')), "{printed}");
    }
}
