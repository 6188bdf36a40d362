//! Line charts for reports, written as both SVG and PNG (`plotters`, with a small
//! bundled font so that no system font is needed).

use std::io;
use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;

/// DejaVu Sans reduced to the characters plot labels use (licence in
/// `sims/assets/DejaVuSans-LICENSE.txt`).
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans-subset.ttf");
const FAMILY: &str = "sans-serif";
const SIZE_PX: (u32, u32) = (900, 560);
/// Lines of at most this many points are drawn with a marker on each.
const MARKED_POINTS: usize = 12;

/// One line, optionally with a shaded band (for example a 95% confidence interval).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub label: String,
    /// The line's points `(x, y)`; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
    /// Band around the line as `(x, low, high)`; empty for none.
    pub band: Vec<(f64, f64, f64)>,
    /// Draw the line dashed.
    pub dashed: bool,
    /// Palette index of its colour; `None`: the series' own index.
    pub colour: Option<usize>,
}

/// A chart: title, axis labels and lines.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Chart {
    /// Caption.
    pub title: String,
    /// Horizontal axis label (with unit).
    pub x_label: String,
    /// Vertical axis label (with unit).
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

impl Chart {
    /// The data range, padded; `[0, 1]` on an axis with no finite data.
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let mut x = (f64::INFINITY, f64::NEG_INFINITY);
        let mut y = (f64::INFINITY, f64::NEG_INFINITY);
        let mut add = |px: f64, py: f64| {
            if px.is_finite() && py.is_finite() {
                x = (x.0.min(px), x.1.max(px));
                y = (y.0.min(py), y.1.max(py));
            }
        };
        for s in &self.series {
            s.points.iter().for_each(|&(px, py)| add(px, py));
            for &(px, lo, hi) in &s.band {
                add(px, lo);
                add(px, hi);
            }
        }
        let pad = |(lo, hi): (f64, f64)| {
            if !(lo.is_finite() && hi.is_finite()) {
                (0.0, 1.0)
            } else if hi - lo < 1e-12 {
                (lo - 0.5, hi + 0.5)
            } else {
                (lo, hi + 0.02 * (hi - lo))
            }
        };
        (pad(x), pad(y))
    }
}

fn font_ready() -> io::Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(io::Error::other(
            "the bundled plot font could not be loaded",
        ))
    }
}

fn err<E: std::error::Error + Send + Sync>(e: DrawingAreaErrorKind<E>) -> io::Error {
    io::Error::other(e.to_string())
}

/// Draws `charts` on `root`, `columns` to a row, and writes the result out.
fn draw_all<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    charts: &[Chart],
    columns: usize,
) -> io::Result<()>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE).map_err(err)?;
    let columns = columns.clamp(1, charts.len().max(1));
    let rows = charts.len().div_ceil(columns).max(1);
    for (area, chart) in root.split_evenly((rows, columns)).iter().zip(charts) {
        draw(area, chart)?;
    }
    root.present().map_err(err)
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, chart: &Chart) -> io::Result<()>
where
    DB::ErrorType: 'static,
{
    let ((x0, x1), (y0, y1)) = chart.ranges();
    let mut c = ChartBuilder::on(root)
        .caption(&chart.title, (FAMILY, 22))
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(76)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(err)?;
    c.configure_mesh()
        .x_desc(chart.x_label.as_str())
        .y_desc(chart.y_label.as_str())
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 15))
        .draw()
        .map_err(err)?;
    for (i, s) in chart.series.iter().enumerate() {
        let color = Palette99::pick(s.colour.unwrap_or(i)).to_rgba();
        let band: Vec<(f64, f64, f64)> = s
            .band
            .iter()
            .copied()
            .filter(|(x, lo, hi)| x.is_finite() && lo.is_finite() && hi.is_finite())
            .collect();
        if band.len() >= 2 {
            let outline: Vec<(f64, f64)> = band
                .iter()
                .map(|&(x, _, hi)| (x, hi))
                .chain(band.iter().rev().map(|&(x, lo, _)| (x, lo)))
                .collect();
            c.draw_series(std::iter::once(Polygon::new(
                outline,
                color.mix(0.18).filled(),
            )))
            .map_err(err)?;
        }
        let points: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .collect();
        let style = color.stroke_width(2);
        // A line of a few points (a figure per coverage level) shows each point.
        if points.len() <= MARKED_POINTS {
            c.draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))
                .map_err(err)?;
        }
        let drawn = if s.dashed {
            c.draw_series(DashedLineSeries::new(points, 8, 5, style))
        } else {
            c.draw_series(LineSeries::new(points, style))
        };
        let legend = if s.dashed { 8 } else { 20 };
        drawn
            .map_err(err)?
            .label(s.label.as_str())
            .legend(move |(x, y)| {
                // A dashed line's legend shows its dash and gap.
                PathElement::new(vec![(x, y), (x + legend, y)], style)
            });
    }
    if chart.series.iter().any(|s| !s.label.is_empty()) {
        c.configure_series_labels()
            .label_font((FAMILY, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

/// Writes `dir/<stem>.svg` and `dir/<stem>.png`.
///
/// # Errors
///
/// Any I/O or drawing error.
pub fn write_chart(chart: &Chart, dir: &Path, stem: &str) -> io::Result<()> {
    write_panels(std::slice::from_ref(chart), 1, dir, stem)
}

/// Writes `dir/<stem>.svg` and `dir/<stem>.png`: the charts as panels of one figure,
/// `columns` to a row, each panel the size of a single chart.
///
/// # Errors
///
/// Any I/O or drawing error.
pub fn write_panels(charts: &[Chart], columns: usize, dir: &Path, stem: &str) -> io::Result<()> {
    font_ready()?;
    let columns = columns.clamp(1, charts.len().max(1));
    let rows = charts.len().div_ceil(columns).max(1);
    let size = (SIZE_PX.0 * columns as u32, SIZE_PX.1 * rows as u32);
    let svg = dir.join(format!("{stem}.svg"));
    let png = dir.join(format!("{stem}.png"));
    draw_all(
        &SVGBackend::new(&svg, size).into_drawing_area(),
        charts,
        columns,
    )?;
    // Drawn into memory and encoded with `png`, so that plotters needs no image crate.
    let mut rgb = vec![0u8; size.0 as usize * size.1 as usize * 3];
    draw_all(
        &BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area(),
        charts,
        columns,
    )?;
    write_rgb_png(&png, size, &rgb)
}

/// Writes 8-bit RGB pixels, row by row, as a PNG file.
fn write_rgb_png(path: &Path, (width, height): (u32, u32), rgb: &[u8]) -> io::Result<()> {
    let file = io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(io::Error::other)?;
    writer.write_image_data(rgb).map_err(io::Error::other)?;
    writer.finish().map_err(io::Error::other)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charts_are_written_as_svg_and_png() {
        let dir = tempfile::tempdir().expect("temp dir");
        let chart = Chart {
            title: "coverage".into(),
            x_label: "time (s)".into(),
            y_label: "coverage (%)".into(),
            series: vec![Series {
                label: "gmm".into(),
                points: vec![(0.0, 0.0), (1.0, 10.0), (2.0, f64::NAN), (3.0, 30.0)],
                band: vec![(0.0, 0.0, 0.0), (1.0, 8.0, 12.0), (3.0, 25.0, 35.0)],
                dashed: true,
                colour: Some(3),
            }],
        };
        write_chart(&chart, dir.path(), "c").expect("chart written");
        let svg = std::fs::read_to_string(dir.path().join("c.svg")).expect("svg");
        assert!(svg.contains("coverage") && svg.contains("gmm"));
        // The PNG decodes to the chart: a white page with the lines and text drawn on it.
        let file = std::fs::File::open(dir.path().join("c.png")).expect("png");
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .expect("png header");
        let mut rgb = vec![0; reader.output_buffer_size().expect("size")];
        let info = reader.next_frame(&mut rgb).expect("png pixels");
        assert_eq!((info.width, info.height), SIZE_PX);
        let white = rgb.chunks(3).filter(|p| p == &[255, 255, 255]).count();
        let pixels = rgb.len() / 3;
        assert!(
            white > pixels / 2 && white < pixels,
            "{white} of {pixels} white"
        );
        // An empty chart still draws its axes.
        write_chart(&Chart::default(), dir.path(), "empty").expect("empty chart written");
        // Panels: three charts, two to a row, make a figure two charts wide and tall.
        let three = [chart.clone(), Chart::default(), chart];
        write_panels(&three, 2, dir.path(), "panels").expect("panels written");
        let png = std::fs::read(dir.path().join("panels.png")).expect("png");
        // The IHDR chunk: width and height, big-endian, at bytes 16–23.
        let be = |at: usize| u32::from_be_bytes([png[at], png[at + 1], png[at + 2], png[at + 3]]);
        assert_eq!((be(16), be(20)), (2 * SIZE_PX.0, 2 * SIZE_PX.1));
    }
}
