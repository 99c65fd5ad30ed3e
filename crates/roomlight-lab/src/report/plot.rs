//! The plots of the demo's and the bench's reports (SVG, plotters): signed quantities on a
//! symmetric log scale so that negative values show, the legend below the plot where it covers
//! no curve, and vertical markers for events (a projector leaves, another joins).

use anyhow::Result;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

/// A linear axis (in transformed units) whose ticks are the ones given: plotters' own f64 axis
/// picks its ticks itself.
#[derive(Debug, Clone)]
struct TickedAxis {
    range: Range<f64>,
    ticks: Vec<f64>,
}

impl Ranged for TickedAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        // An empty range maps everything to its start rather than dividing by zero.
        let span = self.range.end - self.range.start;
        let f = if span > 0.0 {
            (value - self.range.start) / span
        } else {
            0.0
        };
        limit.0 + (f * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<H: KeyPointHint>(&self, _hint: H) -> Vec<f64> {
        self.ticks.clone()
    }

    fn range(&self) -> Range<f64> {
        self.range.clone()
    }
}

/// How the y axis maps values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum YScale {
    /// Linear, from min(0, smallest value) to the largest.
    Linear,
    /// `sign(y)·log10(1 + |y|/t)`: logarithmic beyond the threshold `t`, linear inside it, so
    /// zero and negative values show (matplotlib's "symlog").
    SymLog(f64),
}

impl YScale {
    fn forward(self, y: f64) -> f64 {
        match self {
            Self::Linear => y,
            Self::SymLog(t) => y.signum() * (y.abs() / t).ln_1p() / std::f64::consts::LN_10,
        }
    }

    fn inverse(self, v: f64) -> f64 {
        match self {
            Self::Linear => v,
            Self::SymLog(t) => v.signum() * t * (10f64.powf(v.abs()) - 1.0),
        }
    }

    /// Tick values (in data units) covering `[lo, hi]`.
    fn ticks(self, lo: f64, hi: f64) -> Vec<f64> {
        match self {
            Self::Linear => {
                let step = nice_step((hi - lo) / 6.0);
                let first = (lo / step).ceil() as i64;
                let last = (hi / step).floor() as i64;
                (first..=last).map(|k| k as f64 * step).collect()
            }
            Self::SymLog(t) => {
                let mut v = vec![0.0];
                let mut d = 10f64.powf(t.log10().ceil());
                while d <= hi.abs().max(lo.abs()) * 1.0001 {
                    if d <= hi {
                        v.push(d);
                    }
                    if -d >= lo {
                        v.push(-d);
                    }
                    d *= 10.0;
                }
                v.sort_by(f64::total_cmp);
                v
            }
        }
    }
}

/// 1, 2 or 5 times a power of ten, at least `raw` (1 for a raw step that is not positive).
fn nice_step(raw: f64) -> f64 {
    if !(raw.is_finite() && raw > 0.0) {
        return 1.0;
    }
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * p)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * p)
}

/// A tick label: plain from 0.01 to 100, else a power of ten.
fn tick_label(y: f64) -> String {
    if y.abs() < 1e-12 {
        return "0".into();
    }
    let e = y.abs().log10().round();
    if (-2.0..=2.0).contains(&e) {
        let s = format!("{y:.2}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{y:.0e}")
    }
}

/// An event on the x axis: a dashed vertical line with a label at the top.
#[derive(Debug, Clone)]
pub(crate) struct Marker {
    pub x: f64,
    pub label: String,
}

/// One figure.
#[derive(Debug)]
pub(crate) struct Figure<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub series: &'a [(&'a str, Vec<(f64, f64)>)],
    pub y: YScale,
    pub markers: &'a [Marker],
}

const COLOURS: [RGBColor; 6] = [
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(0, 0, 0),
    RGBColor(23, 190, 207),
];

/// Height of the plot itself; the legend adds a row per series below it.
const PLOT_H: u32 = 380;

/// Writes `figure` as an SVG at `path`. Values that are not finite are left out.
pub(crate) fn plot(path: &Path, figure: &Figure<'_>) -> Result<()> {
    let fail = |e: &dyn std::fmt::Display| anyhow::anyhow!("plot {}: {e}", path.display());
    let rows = figure.series.len() as u32;
    let area = SVGBackend::new(path, (720, PLOT_H + 14 + 20 * rows)).into_drawing_area();
    area.fill(&WHITE).map_err(|e| fail(&e))?;
    let (top, bottom) = area.split_vertically(PLOT_H);
    let points = || {
        figure
            .series
            .iter()
            .flat_map(|(_, s)| s.iter())
            .filter(|p| p.0.is_finite() && p.1.is_finite())
    };
    let (x_lo, x_hi) = points().fold((0.0f64, 1e-3f64), |(a, b), p| (a.min(p.0), b.max(p.0)));
    let (y_lo, y_hi) = points().fold((0.0f64, 0.0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let y_hi = if y_hi > y_lo { y_hi } else { y_lo + 1.0 };
    let scale = figure.y;
    let (t_lo, t_hi) = (scale.forward(y_lo), scale.forward(y_hi));
    let pad = 0.05 * (t_hi - t_lo);
    let keys: Vec<f64> = scale
        .ticks(y_lo, y_hi)
        .into_iter()
        .map(|v| scale.forward(v))
        .collect();
    let mut chart = ChartBuilder::on(&top)
        .caption(figure.title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(64)
        .build_cartesian_2d(
            x_lo..x_hi,
            TickedAxis {
                range: t_lo - if y_lo < 0.0 { pad } else { 0.0 }..t_hi + pad,
                ticks: keys,
            },
        )
        .map_err(|e| fail(&e))?;
    chart
        .configure_mesh()
        .x_desc(figure.x_label)
        .y_desc(figure.y_label)
        .x_label_formatter(&|v| {
            // Whole numbers (captures) without a decimal point.
            if (v - v.round()).abs() < 1e-9 {
                format!("{}", v.round())
            } else {
                format!("{v:.1}")
            }
        })
        .y_label_formatter(&|v| tick_label(scale.inverse(*v)))
        .draw()
        .map_err(|e| fail(&e))?;
    if y_lo < 0.0 {
        chart
            .draw_series(LineSeries::new(
                [(x_lo, 0.0), (x_hi, 0.0)],
                BLACK.mix(0.5).stroke_width(1),
            ))
            .map_err(|e| fail(&e))?;
    }
    for m in figure.markers {
        chart
            .draw_series(DashedLineSeries::new(
                [(m.x, t_lo), (m.x, t_hi + pad)],
                6,
                4,
                BLACK.stroke_width(1),
            ))
            .map_err(|e| fail(&e))?;
        chart
            .draw_series(std::iter::once(Text::new(
                m.label.clone(),
                (m.x, t_hi + pad),
                ("sans-serif", 13).into_font().color(&BLACK),
            )))
            .map_err(|e| fail(&e))?;
    }
    for ((_, s), colour) in figure.series.iter().zip(COLOURS.iter().cycle()) {
        let line: Vec<(f64, f64)> = s
            .iter()
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .map(|&(x, y)| (x, scale.forward(y)))
            .collect();
        chart
            .draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))
            .map_err(|e| fail(&e))?;
        chart
            .draw_series(line.into_iter().map(|p| Circle::new(p, 2, colour.filled())))
            .map_err(|e| fail(&e))?;
    }
    for (i, ((label, _), colour)) in figure.series.iter().zip(COLOURS.iter().cycle()).enumerate() {
        let y = 10 + 20 * i as i32;
        bottom
            .draw(&PathElement::new(
                [(76, y), (106, y)],
                colour.stroke_width(3),
            ))
            .map_err(|e| fail(&e))?;
        bottom
            .draw(&Text::new(
                label.to_string(),
                (114, y - 7),
                ("sans-serif", 14).into_font(),
            ))
            .map_err(|e| fail(&e))?;
    }
    area.present().map_err(|e| fail(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symlog_is_odd_invertible_and_keeps_negative_values() {
        let s = YScale::SymLog(1e-4);
        for y in [-0.3, -1e-3, 0.0, 5e-5, 1e-2, 7.0] {
            assert!((s.inverse(s.forward(y)) - y).abs() <= 1e-12 * y.abs().max(1.0));
            assert!((s.forward(-y) + s.forward(y)).abs() < 1e-12);
        }
        assert!(s.forward(-1e-3) < 0.0);
        assert_eq!(
            s.ticks(-2e-3, 0.5),
            vec![-1e-3, -1e-4, 0.0, 1e-4, 1e-3, 1e-2, 0.1]
        );
        assert_eq!(tick_label(-1e-3), "-1e-3");
        assert_eq!(tick_label(0.1), "0.1");
        assert_eq!(tick_label(10.0), "10");
        assert!((nice_step(0.7) - 1.0).abs() < 1e-12);
        assert!((nice_step(0.0) - 1.0).abs() < 1e-12);
        assert_eq!(
            YScale::Linear.ticks(0.0, 12.0),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0]
        );
    }

    #[test]
    fn a_plot_with_negative_values_markers_and_a_legend_is_written() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("p.svg");
        let series = [
            ("a", vec![(0.0, 1.0), (1.0, 1e-2), (2.0, -3e-3)]),
            ("b", vec![(0.0, 0.5), (1.0, f64::NAN), (2.0, 2e-4)]),
        ];
        let markers = [Marker {
            x: 1.0,
            label: "joins".into(),
        }];
        plot(
            &path,
            &Figure {
                title: "t",
                x_label: "captures",
                y_label: "excess",
                series: &series,
                y: YScale::SymLog(1e-4),
                markers: &markers,
            },
        )
        .expect("plot");
        let svg = std::fs::read_to_string(&path).expect("read");
        assert!(svg.contains("-1e-3"), "a negative tick is labelled");
        assert!(svg.contains("joins"));
        assert!(
            svg.contains("\na\n") && svg.contains("\nb\n"),
            "legend labels"
        );
    }
}
