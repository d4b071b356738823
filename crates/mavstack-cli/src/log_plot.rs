//! `mavstack log plot`: time series of message fields from a log, drawn with plotters into a
//! PNG or SVG image: one series per field and source, axes labelled with the units the
//! dialect's XML gives.

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use clap::Args;
use mavstack_core::MAX_PAYLOAD_LEN;
use mavstack_xml::codec::{self, Value};
use mavstack_xml::{Dialect, Field, Message, PrimitiveType};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::Failure;
use crate::log_reader::read_log;

/// `mavstack log plot`.
#[derive(Debug, Args)]
pub(crate) struct PlotArgs {
    /// A tlog (`.tlog`) or a raw MAVLink capture.
    file: PathBuf,
    /// Fields to plot: `MESSAGE.field`, or `MESSAGE.field[i]` for an element of an array.
    #[arg(required = true, value_name = "FIELD")]
    fields: Vec<String>,
    /// The image to write: PNG or SVG, by its extension.
    #[arg(long, value_name = "PATH")]
    out: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 1200, value_parser = clap::value_parser!(u32).range(200..=20_000))]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 600, value_parser = clap::value_parser!(u32).range(150..=20_000))]
    height: u32,
    /// Only frames from this system id.
    #[arg(long, value_name = "N")]
    sysid: Option<u8>,
    /// A built-in dialect name or a path to an XML file (message names, fields and units).
    #[arg(long, default_value = "ardupilotmega")]
    dialect: String,
    /// A TrueType font for the labels (default: DejaVu Sans or Liberation Sans from the
    /// usual system paths; also the MAVSTACK_FONT environment variable).
    #[arg(long, value_name = "TTF")]
    font: Option<PathBuf>,
}

/// One requested field.
struct Wanted<'d> {
    /// As the user wrote it.
    spec: String,
    message: &'d Message,
    field: &'d Field,
    /// The element of an array field.
    index: Option<usize>,
}

impl Wanted<'_> {
    fn value(&self, buf: &[u8; MAX_PAYLOAD_LEN]) -> Option<f64> {
        match (codec::decode_field(self.field, buf), self.index) {
            (Value::Array(items), Some(i)) => items.get(i).and_then(Value::as_f64),
            (v, None) => v.as_f64(),
            _ => None,
        }
    }

    fn units(&self) -> Option<&str> {
        self.field.units.as_deref()
    }
}

fn parse_field<'d>(dialect: &'d Dialect, spec: &str) -> Result<Wanted<'d>, Failure> {
    let bad = |why: String| Failure::Input(anyhow!("field {spec}: {why}"));
    let (name, rest) = spec
        .split_once('.')
        .ok_or_else(|| bad("expected MESSAGE.field or MESSAGE.field[i]".into()))?;
    let (field_name, index) = match rest.split_once('[') {
        Some((f, i)) => {
            let i = i
                .strip_suffix(']')
                .and_then(|i| i.parse::<usize>().ok())
                .ok_or_else(|| bad("expected an index such as [0]".into()))?;
            (f, Some(i))
        }
        None => (rest, None),
    };
    let message = dialect
        .messages
        .iter()
        .find(|m| m.name.eq_ignore_ascii_case(name))
        .ok_or_else(|| bad(format!("no message {name} in dialect {}", dialect.name)))?;
    let field = message
        .fields
        .iter()
        .find(|f| f.name.eq_ignore_ascii_case(field_name))
        .ok_or_else(|| {
            let names: Vec<&str> = message
                .fields_in_xml_order()
                .iter()
                .map(|f| f.name.as_str())
                .collect();
            bad(format!(
                "{} has no field {field_name}; its fields: {}",
                message.name,
                names.join(", ")
            ))
        })?;
    if field.ty.primitive == PrimitiveType::Char {
        return Err(bad(format!(
            "{}.{} is text, not a number",
            message.name, field.name
        )));
    }
    match (field.ty.array_len, index) {
        (Some(n), None) => {
            return Err(bad(format!(
                "{}.{} is an array of {n}: give an element, {}.{}[0]",
                message.name, field.name, message.name, field.name
            )));
        }
        (Some(n), Some(i)) if i >= usize::from(n) => {
            return Err(bad(format!("index {i} is beyond the array's {n} elements")));
        }
        (None, Some(_)) => {
            return Err(bad(format!(
                "{}.{} is not an array",
                message.name, field.name
            )));
        }
        _ => {}
    }
    Ok(Wanted {
        spec: match index {
            Some(i) => format!("{}.{}[{i}]", message.name, field.name),
            None => format!("{}.{}", message.name, field.name),
        },
        message,
        field,
        index,
    })
}

/// Series colours, distinct from each other and from the black and grey of the axes.
const PALETTE: [RGBColor; 10] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0x17, 0xbe, 0xcf),
    RGBColor(0xbc, 0xbd, 0x22),
    RGBColor(0x00, 0x3f, 0x5c),
];

/// One series: a field from one source.
struct Series {
    label: String,
    colour: RGBColor,
    /// The panel it is drawn in: one per unit.
    panel: usize,
    points: Vec<(f64, f64)>,
}

/// Where a font for the labels may be on common systems.
const FONT_PATHS: [&str; 6] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "C:\\Windows\\Fonts\\arial.ttf",
];

fn load_font(given: Option<&Path>) -> Result<(), Failure> {
    let from_env = std::env::var_os("MAVSTACK_FONT").map(PathBuf::from);
    let path = given
        .map(Path::to_path_buf)
        .or(from_env)
        .or_else(|| FONT_PATHS.iter().map(PathBuf::from).find(|p| p.is_file()))
        .ok_or_else(|| {
            Failure::Other(anyhow!(
                "no TrueType font for the plot's labels: give --font FILE.ttf or set \
                 MAVSTACK_FONT (Debian: apt-get install fonts-dejavu-core)"
            ))
        })?;
    let bytes = std::fs::read(&path)
        .with_context(|| format!("font {}", path.display()))
        .map_err(Failure::Input)?;
    // The font lives as long as the process: plotters keeps a reference to it.
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
        .map_err(|_| Failure::Input(anyhow!("font {}: not a TrueType font", path.display())))
}

/// At most this many points per pixel column are kept (the column's first, lowest,
/// highest and last), so a long log draws its envelope in bounded time and file size.
fn decimate(points: &[(f64, f64)], x0: f64, x1: f64, columns: u32) -> Vec<(f64, f64)> {
    if points.len() <= 4 * columns as usize || x1 <= x0 {
        return points.to_vec();
    }
    let width = (x1 - x0) / f64::from(columns);
    let mut out = Vec::with_capacity(4 * columns as usize + 4);
    let mut i = 0;
    while i < points.len() {
        let column = ((points[i].0 - x0) / width).floor();
        let start = i;
        while i < points.len() && ((points[i].0 - x0) / width).floor() == column {
            i += 1;
        }
        let bucket = &points[start..i];
        let by_y = |a: &&(f64, f64), b: &&(f64, f64)| a.1.total_cmp(&b.1);
        let lo = bucket.iter().enumerate().min_by(|a, b| by_y(&a.1, &b.1));
        let hi = bucket.iter().enumerate().max_by(|a, b| by_y(&a.1, &b.1));
        let mut keep = vec![0, bucket.len() - 1];
        keep.extend(lo.map(|(k, _)| k));
        keep.extend(hi.map(|(k, _)| k));
        keep.sort_unstable();
        keep.dedup();
        out.extend(keep.into_iter().map(|k| bucket[k]));
    }
    out
}

pub(crate) fn plot(args: &PlotArgs) -> Result<(), Failure> {
    let svg = match args
        .out
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .as_deref()
    {
        Some("png") => false,
        Some("svg") => true,
        _ => {
            return Err(Failure::Input(anyhow!(
                "--out {}: the image's name must end in .png or .svg",
                args.out.display()
            )));
        }
    };
    let dialect = crate::dialect_cmd::load(&args.dialect)?;
    let wanted: Vec<Wanted<'_>> = args
        .fields
        .iter()
        .map(|f| parse_field(&dialect, f))
        .collect::<Result<_, _>>()?;
    load_font(args.font.as_deref())?;
    // (wanted index, sysid, compid) → points (seconds from the log's start, value).
    let mut series: BTreeMap<(usize, u8, u8), Vec<(f64, f64)>> = BTreeMap::new();
    let mut first: Option<u64> = None;
    let mut index = 0u64;
    let mut buf = [0u8; MAX_PAYLOAD_LEN];
    let counts = read_log(&args.file, &dialect, "plot", |f| {
        let x = match f.ts_us {
            Some(ts) => ts.saturating_sub(*first.get_or_insert(ts)) as f64 / 1e6,
            None => index as f64,
        };
        index += 1;
        let frame = &f.frame;
        if !f.known || args.sysid.is_some_and(|s| s != frame.sysid()) {
            return;
        }
        let id = frame.msg_id();
        if !wanted.iter().any(|w| w.message.id == id) {
            return;
        }
        let payload = frame.payload();
        buf.fill(0);
        let n = payload.len().min(MAX_PAYLOAD_LEN);
        buf[..n].copy_from_slice(&payload[..n]);
        for (i, w) in wanted
            .iter()
            .enumerate()
            .filter(|(_, w)| w.message.id == id)
        {
            if let Some(y) = w.value(&buf).filter(|y| y.is_finite()) {
                series
                    .entry((i, frame.sysid(), frame.compid()))
                    .or_default()
                    .push((x, y));
            }
        }
    })?;
    let timed = first.is_some();
    let sources: std::collections::BTreeSet<(u8, u8)> =
        series.keys().map(|&(_, s, c)| (s, c)).collect();
    let many_sources = sources.len() > 1;
    // One panel per unit, in the order the fields were given: a value in mm and an angle in
    // rad each get an axis scaled for them.
    let mut panels: Vec<String> = Vec::new();
    for w in &wanted {
        let unit = w.units().unwrap_or("value").to_owned();
        if !panels.contains(&unit) {
            panels.push(unit);
        }
    }
    let mut drawn: Vec<Series> = Vec::new();
    for (n, ((i, sysid, compid), points)) in series.into_iter().enumerate() {
        let w = &wanted[i];
        let mut label = w.spec.clone();
        if let Some(u) = w.units() {
            label.push_str(&format!(" [{u}]"));
        }
        if many_sources {
            label.push_str(&format!(" ({sysid}/{compid})"));
        }
        let colour = PALETTE[n % PALETTE.len()];
        println!(
            "series {} sysid={sysid} compid={compid} points={} colour=#{:02x}{:02x}{:02x}",
            w.spec,
            points.len(),
            colour.0,
            colour.1,
            colour.2
        );
        let unit = w.units().unwrap_or("value");
        drawn.push(Series {
            label,
            colour,
            panel: panels.iter().position(|p| p == unit).unwrap_or(0),
            points,
        });
    }
    for w in &wanted {
        if !drawn.iter().any(|s| s.label.starts_with(&w.spec)) {
            eprintln!("warning: no {} in {}", w.spec, args.file.display());
        }
    }
    let _ = std::io::stdout().flush();
    let x_desc = if timed {
        "time since the log's first frame [s]"
    } else {
        "frame number (a raw capture has no timestamps)"
    };
    let title = format!(
        "{} — {}",
        args.file.file_name().map_or_else(
            || args.file.display().to_string(),
            |n| n.to_string_lossy().into_owned()
        ),
        args.fields.join(", ")
    );
    let chart = Chart {
        title: &title,
        x_desc,
        panels: &panels,
        series: &drawn,
        x_end: if timed { 0.0 } else { counts.frames as f64 },
        columns: args.width,
    };
    let size = (args.width, args.height);
    let result = if svg {
        chart.draw(SVGBackend::new(&args.out, size).into_drawing_area())
    } else {
        chart.draw(BitMapBackend::new(&args.out, size).into_drawing_area())
    };
    result
        .with_context(|| format!("drawing {}", args.out.display()))
        .map_err(Failure::Other)
}

/// What to draw.
struct Chart<'a> {
    title: &'a str,
    x_desc: &'a str,
    /// Each panel's unit, top to bottom.
    panels: &'a [String],
    series: &'a [Series],
    /// The x axis reaches at least this far.
    x_end: f64,
    /// Pixel columns, for decimation.
    columns: u32,
}

impl Chart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> anyhow::Result<()>
    where
        DB::ErrorType: 'static,
    {
        let error = anyhow::Error::new::<DrawingAreaErrorKind<DB::ErrorType>>;
        root.fill(&WHITE).map_err(error)?;
        let body = root.titled(self.title, ("sans-serif", 18)).map_err(error)?;
        let (mut x0, mut x1) = (0.0f64, self.x_end);
        for &(x, _) in self.series.iter().flat_map(|s| s.points.iter()) {
            x0 = x0.min(x);
            x1 = x1.max(x);
        }
        if x1 <= x0 {
            x1 = x0 + 1.0;
        }
        let areas = body.split_evenly((self.panels.len().max(1), 1));
        for (panel, (area, unit)) in areas.iter().zip(self.panels).enumerate() {
            let series: Vec<&Series> = self.series.iter().filter(|s| s.panel == panel).collect();
            self.panel(area, unit, &series, (x0, x1)).map_err(error)?;
        }
        root.present().map_err(error)
    }

    fn panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        unit: &str,
        series: &[&Series],
        (x0, x1): (f64, f64),
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let (mut y0, mut y1) = (f64::MAX, f64::MIN);
        for &(_, y) in series.iter().flat_map(|s| s.points.iter()) {
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if y0 > y1 {
            (y0, y1) = (0.0, 1.0);
        }
        let pad = if y1 > y0 { (y1 - y0) * 0.05 } else { 1.0 };
        let mut chart = ChartBuilder::on(area)
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(72)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))?;
        chart
            .configure_mesh()
            .x_desc(self.x_desc)
            .y_desc(unit)
            .light_line_style(RGBColor(0xee, 0xee, 0xee))
            .draw()?;
        for s in series {
            let colour = s.colour;
            let points = decimate(&s.points, x0, x1, self.columns);
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(2)))?
                .label(s.label.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], colour.stroke_width(3))
                });
        }
        if !series.is_empty() {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperRight)
                .draw()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error(dialect: &Dialect, spec: &str) -> String {
        match parse_field(dialect, spec) {
            Err(Failure::Input(e)) => e.to_string(),
            Err(Failure::Other(e)) => panic!("{spec}: not a usage error: {e}"),
            Ok(w) => panic!("{spec}: parsed as {}", w.spec),
        }
    }

    #[test]
    fn fields_resolve_in_the_dialect_with_their_units_and_bad_ones_say_why() {
        let d = mavstack_xml::load("common").expect("common");
        let w = parse_field(&d, "attitude.ROLL").expect("ATTITUDE.roll");
        assert_eq!((w.spec.as_str(), w.units()), ("ATTITUDE.roll", Some("rad")));
        let w = parse_field(&d, "SERVO_OUTPUT_RAW.servo3_raw").expect("a scalar");
        assert_eq!(w.index, None);
        let w = parse_field(&d, "GPS_STATUS.satellite_snr[3]").expect("an element");
        assert_eq!(
            (w.spec.as_str(), w.index),
            ("GPS_STATUS.satellite_snr[3]", Some(3))
        );
        assert!(error(&d, "ATTITUDE").contains("expected MESSAGE.field"));
        assert!(error(&d, "NOPE.x").contains("no message NOPE"));
        let e = error(&d, "ATTITUDE.rol");
        assert!(
            e.contains("no field rol") && e.contains("roll, pitch, yaw"),
            "{e}"
        );
        assert!(error(&d, "GPS_STATUS.satellite_snr").contains("an array of 20"));
        assert!(error(&d, "GPS_STATUS.satellite_snr[20]").contains("beyond"));
        assert!(error(&d, "GPS_STATUS.satellite_snr[x]").contains("index"));
        assert!(error(&d, "ATTITUDE.roll[0]").contains("not an array"));
        assert!(error(&d, "STATUSTEXT.text").contains("is text"));
    }

    #[test]
    fn a_field_reads_from_a_truncated_payload_as_zero_extended() {
        let d = mavstack_xml::load("common").expect("common");
        let w = parse_field(&d, "ATTITUDE.pitch").expect("pitch");
        let mut buf = [0u8; MAX_PAYLOAD_LEN];
        buf[8..12].copy_from_slice(&(-0.25f32).to_le_bytes());
        assert_eq!(w.value(&buf), Some(-0.25));
        let w = parse_field(&d, "GPS_STATUS.satellite_snr[1]").expect("an element");
        buf.fill(0);
        buf[w.field.offset + 1] = 42;
        assert_eq!(w.value(&buf), Some(42.0));
    }

    #[test]
    fn decimation_keeps_each_columns_first_lowest_highest_and_last_point() {
        let points: Vec<(f64, f64)> = (0..10_000)
            .map(|i| {
                (
                    f64::from(i) / 100.0,
                    f64::from(i % 7) - if i == 5_000 { 50.0 } else { 0.0 },
                )
            })
            .collect();
        let kept = decimate(&points, 0.0, 100.0, 10);
        assert!(kept.len() <= 40, "{} points kept", kept.len());
        assert_eq!(kept.first(), points.first());
        assert_eq!(kept.last(), points.last());
        assert!(
            kept.contains(&(50.0, -50.0 + f64::from(5_000 % 7))),
            "the spike is kept"
        );
        assert!(kept.windows(2).all(|w| w[0].0 <= w[1].0), "in time order");
        let few = &points[..30];
        assert_eq!(decimate(few, 0.0, 1.0, 10), few);
    }
}
