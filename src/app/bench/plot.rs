//! SVG plots of a benchmark sweep: the overview of frame times against size, the stacked
//! per-stage times and the breakdown of one run.

use super::report::BenchReport;

/// Stage and series colours: Tableau 10 without its yellow, readable on white and told
/// apart by most colour-blind readers.
const PALETTE: [(u8, u8, u8); 9] = [
    (78, 121, 167),
    (242, 142, 43),
    (225, 87, 89),
    (118, 183, 178),
    (89, 161, 79),
    (176, 122, 161),
    (255, 157, 167),
    (156, 117, 95),
    (186, 176, 172),
];

fn palette(k: usize) -> plotters::style::RGBColor {
    let (r, g, b) = PALETTE[k % PALETTE.len()];
    plotters::style::RGBColor(r, g, b)
}

fn draw_err(e: impl std::fmt::Display) -> String {
    format!("cannot draw the plot: {e}")
}

/// `1k`, `250k`, `1M`, `2.5M`: a Gaussian count for an axis label.
fn count_label(v: f64) -> String {
    let (scaled, unit) = if v >= 1e6 {
        (v / 1e6, "M")
    } else if v >= 1e3 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
    let text = format!("{scaled:.2}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    format!("{text}{unit}")
}

/// Three significant digits at most: `0.058`, `0.23`, `2.07`, `8.29`, `33.2`.
fn value_label(v: f64) -> String {
    if v <= 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.log10().floor() as i32).clamp(0, 6) as usize;
    let text = format!("{v:.digits$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// Tick values for a logarithmic axis over `[lo, hi]`: 1, 2, 5 times powers of ten, or
/// denser steps (1, 1.5, 2, 3, 5, 7) when that gives fewer than three ticks.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    if !(lo > 0.0 && hi >= lo && hi.is_finite()) {
        return Vec::new();
    }
    let mut ticks = Vec::new();
    for mantissas in [&[1.0, 2.0, 5.0][..], &[1.0, 1.5, 2.0, 3.0, 5.0, 7.0][..]] {
        ticks.clear();
        let mut decade = 10f64.powi(lo.log10().floor() as i32);
        while decade <= hi {
            for m in mantissas {
                let t = decade * m;
                if t >= lo * (1.0 - 1e-9) && t <= hi * (1.0 + 1e-9) {
                    ticks.push(t);
                }
            }
            decade *= 10.0;
        }
        if ticks.len() >= 3 {
            break;
        }
    }
    ticks
}

/// One sweep axis: the reports along it, one series per value of the other axis.
struct SeriesGroup<'a> {
    /// Series label (`1280x720` or `10k Gaussians`) and its points, sorted by `x`.
    series: Vec<(String, Vec<(f64, &'a BenchReport)>)>,
}

impl<'a> SeriesGroup<'a> {
    fn x_values(&self) -> Vec<f64> {
        let mut xs: Vec<f64> = self
            .series
            .iter()
            .flat_map(|(_, pts)| pts.iter().map(|p| p.0))
            .collect();
        xs.sort_by(|a, b| a.total_cmp(b));
        xs.dedup();
        xs
    }
}

/// Groups `reports` into series: `key` names the series a report belongs to (the value
/// of the other axis) and `x` places it along this axis.
fn group<'a, K: PartialOrd + Copy>(
    reports: &'a [BenchReport],
    key: impl Fn(&BenchReport) -> K,
    label: impl Fn(&BenchReport) -> String,
    x: impl Fn(&BenchReport) -> f64,
) -> SeriesGroup<'a> {
    let mut keys: Vec<K> = Vec::new();
    for r in reports {
        if !keys.iter().any(|k| *k == key(r)) {
            keys.push(key(r));
        }
    }
    keys.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    let series = keys
        .into_iter()
        .map(|k| {
            let mut pts: Vec<(f64, &BenchReport)> = reports
                .iter()
                .filter(|r| key(r) == k)
                .map(|r| (x(r), r))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            let name = pts.first().map(|p| label(p.1)).unwrap_or_default();
            (name, pts)
        })
        .collect();
    SeriesGroup { series }
}

type Area<'b> =
    plotters::drawing::DrawingArea<plotters::prelude::SVGBackend<'b>, plotters::coord::Shift>;

/// How a legend entry is drawn.
enum Swatch {
    /// A filled square (a stacked stage).
    Fill,
    /// A line with a dot (a series).
    Line,
    /// A dashed black line (the whole frame).
    Dashed,
}

/// Draws a legend into its own area, so it never covers data.
fn draw_legend(
    area: &Area,
    title: &str,
    entries: &[(String, plotters::style::RGBColor, Swatch)],
) -> Result<(), String> {
    use plotters::prelude::*;
    let font = ("sans-serif", 14).into_font();
    area.draw(&Text::new(
        title.to_string(),
        (6, 8),
        font.clone().style(FontStyle::Bold),
    ))
    .map_err(draw_err)?;
    for (i, (label, colour, swatch)) in entries.iter().enumerate() {
        let y = 34 + 22 * i as i32;
        match swatch {
            Swatch::Fill => area
                .draw(&Rectangle::new([(8, y), (24, y + 14)], colour.filled()))
                .map_err(draw_err)?,
            Swatch::Line => {
                area.draw(&PathElement::new(
                    vec![(6, y + 7), (26, y + 7)],
                    colour.stroke_width(2),
                ))
                .map_err(draw_err)?;
                area.draw(&Circle::new((16, y + 7), 3, colour.filled()))
                    .map_err(draw_err)?;
            }
            Swatch::Dashed => {
                for x in [6, 13, 20] {
                    area.draw(&PathElement::new(
                        vec![(x, y + 7), (x + 5, y + 7)],
                        BLACK.stroke_width(2),
                    ))
                    .map_err(draw_err)?;
                }
            }
        }
        area.draw(&Text::new(label.clone(), (32, y), font.clone()))
            .map_err(draw_err)?;
    }
    Ok(())
}

/// Frame time (median) against `x` on log axes, one line per series; the legend goes in
/// `legend`.
fn draw_overview(
    area: &Area,
    legend: &Area,
    title: &str,
    xlabel: &str,
    legend_title: &str,
    group: &SeriesGroup,
    x_label: &dyn Fn(&f64) -> String,
) -> Result<(), String> {
    use plotters::prelude::*;
    let xs = group.x_values();
    let (xmin, xmax) = (xs[0], xs[xs.len() - 1]);
    let ys: Vec<f64> = group
        .series
        .iter()
        .flat_map(|(_, pts)| pts.iter().map(|p| p.1.frame_ms.median))
        .filter(|v| *v > 0.0)
        .collect();
    let ymin = ys.iter().copied().fold(f64::INFINITY, f64::min).min(1e3);
    let ymax = ys.iter().copied().fold(0.0, f64::max).max(1e-3);
    let (ylo, yhi) = (ymin / 1.3, ymax * 1.3);
    let mut yticks = log_ticks(ylo, yhi);
    if yticks.len() < 2 {
        yticks = ys.clone();
    }
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(
            (xmin / 1.15..xmax * 1.15)
                .log_scale()
                .with_key_points(xs.clone()),
            (ylo..yhi).log_scale().with_key_points(yticks),
        )
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(format!("{xlabel} (log)"))
        .y_desc("frame ms (median, log)")
        .x_label_formatter(x_label)
        .y_label_formatter(&|v| value_label(*v))
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()
        .map_err(draw_err)?;
    let mut entries = Vec::new();
    for (k, (name, pts)) in group.series.iter().enumerate() {
        let colour = palette(k);
        let line: Vec<(f64, f64)> = pts
            .iter()
            .map(|(x, r)| (*x, r.frame_ms.median.max(ylo)))
            .collect();
        chart
            .draw_series(LineSeries::new(line.clone(), colour.stroke_width(2)))
            .map_err(draw_err)?;
        chart
            .draw_series(line.into_iter().map(|p| Circle::new(p, 4, colour.filled())))
            .map_err(draw_err)?;
        entries.push((name.clone(), colour, Swatch::Line));
    }
    draw_legend(legend, legend_title, &entries)
}

/// The median stage times of one series stacked as filled areas against `x`, with the
/// whole frame's median as a dashed line over them.
fn draw_stacked(
    area: &Area,
    title: &str,
    xlabel: &str,
    stages: &[String],
    pts: &[(f64, &BenchReport)],
    x_label: &dyn Fn(&f64) -> String,
) -> Result<(), String> {
    use plotters::prelude::*;
    if pts.len() < 2 {
        area.titled(
            &format!("{title}: one point, nothing to plot"),
            ("sans-serif", 15),
        )
        .map_err(draw_err)?;
        return Ok(());
    }
    let xs: Vec<f64> = pts.iter().map(|p| p.0).collect();
    let (xmin, xmax) = (xs[0], xs[xs.len() - 1]);
    let ymax = pts
        .iter()
        .map(|(_, r)| {
            r.frame_ms
                .median
                .max(r.stages.iter().map(|s| s.ms.median).sum())
        })
        .fold(0.0, f64::max)
        * 1.08;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (xmin..xmax).log_scale().with_key_points(xs.clone()),
            0.0..ymax.max(1e-3),
        )
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(format!("{xlabel} (log)"))
        .y_desc("ms (median, stacked)")
        .x_label_formatter(x_label)
        .y_labels(6)
        .y_label_formatter(&|v| value_label(*v))
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()
        .map_err(draw_err)?;
    let mut lower = vec![0.0; pts.len()];
    for (k, name) in stages.iter().enumerate() {
        let upper: Vec<f64> = pts
            .iter()
            .zip(&lower)
            .map(|((_, r), lo)| lo + r.median(name))
            .collect();
        let mut outline: Vec<(f64, f64)> = xs.iter().copied().zip(upper.iter().copied()).collect();
        outline.extend(xs.iter().copied().zip(lower.iter().copied()).rev());
        let colour = palette(k);
        chart
            .draw_series(std::iter::once(Polygon::new(
                outline,
                colour.mix(0.9).filled(),
            )))
            .map_err(draw_err)?;
        chart
            .draw_series(LineSeries::new(
                xs.iter().copied().zip(upper.iter().copied()),
                colour.stroke_width(1),
            ))
            .map_err(draw_err)?;
        lower = upper;
    }
    // The whole frame (the stages plus the barriers between them), dashed.
    let frame: Vec<(f64, f64)> = pts.iter().map(|(x, r)| (*x, r.frame_ms.median)).collect();
    chart
        .draw_series(DashedLineSeries::new(frame, 6, 4, BLACK.stroke_width(2)))
        .map_err(draw_err)?;
    Ok(())
}

/// The median of each stage of one report as bars.
fn draw_breakdown(area: &Area, report: &BenchReport) -> Result<(), String> {
    use plotters::prelude::*;
    let ymax = report
        .stages
        .iter()
        .map(|s| s.ms.median)
        .fold(0.0, f64::max)
        * 1.1;
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "stages at {} Gaussians, {}x{}",
                count_label(report.gaussians as f64),
                report.width,
                report.height
            ),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (0..report.stages.len()).into_segmented(),
            0.0..ymax.max(1e-3),
        )
        .map_err(draw_err)?;
    let names: Vec<String> = report.stages.iter().map(|s| s.name.clone()).collect();
    chart
        .configure_mesh()
        .x_labels(names.len())
        .x_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) => names.get(*i).cloned().unwrap_or_default(),
            _ => String::new(),
        })
        .y_desc("ms (median)")
        .y_label_formatter(&|v| value_label(*v))
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()
        .map_err(draw_err)?;
    chart
        .draw_series(report.stages.iter().enumerate().map(|(i, s)| {
            Rectangle::new(
                [
                    (SegmentValue::Exact(i), 0.0),
                    (SegmentValue::Exact(i + 1), s.ms.median),
                ],
                palette(i).filled(),
            )
        }))
        .map_err(draw_err)?;
    Ok(())
}

/// An SVG of a sweep. Top row: the frame time against Gaussians (one line per
/// resolution) and against megapixels (one line per Gaussian count), on log axes, and the
/// per-stage breakdown of the largest point. Then, for every resolution, the stage times
/// stacked as filled areas against Gaussians, and for every Gaussian count, against
/// megapixels, each with the whole frame dashed over them. Legends sit beside the plots,
/// never on the data; ticks are at the measured values.
pub fn plot_sweep(reports: &[BenchReport]) -> Result<String, String> {
    use plotters::prelude::*;
    let largest = reports
        .iter()
        .max_by_key(|r| (r.gaussians, r.width as u64 * r.height as u64))
        .ok_or_else(|| draw_err("no reports"))?;
    let stages: Vec<String> = largest.stages.iter().map(|s| s.name.clone()).collect();
    let megapixels = |r: &BenchReport| r.width as f64 * r.height as f64 / 1e6;
    let resolution = |r: &BenchReport| format!("{}x{}", r.width, r.height);
    let by_gaussians = group(
        reports,
        |r| (r.width as u64 * r.height as u64, r.width),
        resolution,
        |r| r.gaussians as f64,
    );
    let by_pixels = group(
        reports,
        |r| r.gaussians,
        |r| format!("{} Gaussians", count_label(r.gaussians as f64)),
        megapixels,
    );
    let vary_gaussians = by_gaussians.x_values().len() > 1;
    let vary_pixels = by_pixels.x_values().len() > 1;
    let count_ticks = |v: &f64| count_label(*v);
    let mp_ticks = |v: &f64| value_label(*v);

    let legend_w = 190u32;
    let row_h = 420u32;
    let stacked_rows: Vec<(&SeriesGroup, &str)> = [
        (vary_gaussians, &by_gaussians, "Gaussians"),
        (vary_pixels, &by_pixels, "megapixels"),
    ]
    .into_iter()
    .filter(|(vary, _, _)| *vary)
    .map(|(_, g, label)| (g, label))
    .collect();
    let columns = stacked_rows
        .iter()
        .map(|(g, _)| g.series.len())
        .max()
        .unwrap_or(1)
        .max(2);
    let width = (legend_w + 360 * columns as u32).max(1500);
    let height = row_h * (1 + stacked_rows.len() as u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(draw_err)?;
        let (top, mut rest) = root.split_vertically(row_h);
        // Top row: overviews and the breakdown, each overview with its legend beside it.
        let overviews = [vary_gaussians, vary_pixels].iter().filter(|v| **v).count();
        let panel_w = width / (overviews as u32 + 1);
        let mut area = top;
        if vary_gaussians {
            let (panel, next) = area.split_horizontally(panel_w);
            let (plot, legend) = panel.split_horizontally(panel_w - 130);
            draw_overview(
                &plot,
                &legend.margin(40, 0, 0, 0),
                "frame time vs Gaussians",
                "Gaussians",
                "resolution",
                &by_gaussians,
                &count_ticks,
            )?;
            area = next;
        }
        if vary_pixels {
            let (panel, next) = area.split_horizontally(panel_w);
            let (plot, legend) = panel.split_horizontally(panel_w - 130);
            draw_overview(
                &plot,
                &legend.margin(40, 0, 0, 0),
                "frame time vs megapixels",
                "megapixels",
                "Gaussians",
                &by_pixels,
                &mp_ticks,
            )?;
            area = next;
        }
        draw_breakdown(&area, largest)?;
        // Stacked rows, one panel per series, and the stage legend in the right column.
        if !stacked_rows.is_empty() {
            let (plots, legend) = rest.split_horizontally(width - legend_w);
            let mut entries: Vec<(String, RGBColor, Swatch)> = stages
                .iter()
                .enumerate()
                .map(|(k, s)| (s.clone(), palette(k), Swatch::Fill))
                .collect();
            entries.reverse(); // top of the stack first
            entries.push(("whole frame".into(), BLACK, Swatch::Dashed));
            draw_legend(&legend.margin(40, 0, 0, 0), "stages", &entries)?;
            rest = plots;
        }
        let mut rows = rest
            .split_evenly((stacked_rows.len().max(1), 1))
            .into_iter();
        for (g, xlabel) in &stacked_rows {
            let Some(row) = rows.next() else { break };
            let panels = row.split_evenly((1, columns));
            for ((name, pts), panel) in g.series.iter().zip(&panels) {
                let (title, ticks): (String, &dyn Fn(&f64) -> String) = if *xlabel == "Gaussians" {
                    (format!("stages vs Gaussians at {name}"), &count_ticks)
                } else {
                    (format!("stages vs megapixels, {name}"), &mp_ticks)
                };
                draw_stacked(panel, &title, xlabel, &stages, pts, ticks)?;
            }
        }
        root.present().map_err(draw_err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_labels_are_short_and_exact_enough() {
        assert_eq!(count_label(300.0), "300");
        assert_eq!(count_label(1000.0), "1k");
        assert_eq!(count_label(1200.0), "1.2k");
        assert_eq!(count_label(250_000.0), "250k");
        assert_eq!(count_label(2.5e6), "2.5M");
        assert_eq!(value_label(0.003072), "0.00307");
        assert_eq!(value_label(0.9216), "0.922");
        assert_eq!(value_label(8.2944), "8.29");
        assert_eq!(value_label(100.0), "100");
        assert_eq!(value_label(0.0), "0");
    }

    #[test]
    fn log_ticks_give_at_least_three_values_inside_the_range() {
        assert_eq!(log_ticks(0.9, 60.0), [1.0, 2.0, 5.0, 10.0, 20.0, 50.0]);
        // Less than a decade: denser steps.
        assert_eq!(log_ticks(68.0, 330.0), [70.0, 100.0, 150.0, 200.0, 300.0]);
        assert!(log_ticks(0.0, 1.0).is_empty());
    }
}
