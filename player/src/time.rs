//! Times in seconds as scripts and the command line write them: one reading for a script's
//! timed lines, its `expect timer ... expires at` deadlines and the options `--until` and
//! `--run-for`, so that what one accepts the others accept.

/// The largest script time, in seconds: mission time is counted in microseconds in a `u64`,
/// and a time past it would silently saturate.
pub const MAX_TIME_S: f64 = u64::MAX as f64 / 1e6;

/// Reads a time in seconds: a finite number from 0 to [`MAX_TIME_S`], nothing else (`nan`,
/// `inf` and `-1` are refused, not clamped).
pub fn parse_time(text: &str) -> Result<f64, String> {
    let time: f64 = text
        .parse()
        .map_err(|_| format!("`{text}` is not a time in seconds"))?;
    if !time.is_finite() || !(0.0..=MAX_TIME_S).contains(&time) {
        return Err(format!(
            "`{text}` is not a time: a time is a number of seconds from 0 to {MAX_TIME_S:e}"
        ));
    }
    Ok(time)
}
