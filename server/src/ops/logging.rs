//! Logs on stderr: readable lines by default, one JSON object per line with `--log-format json`
//! for log collectors (each with its span: the request, or the job and its submission).

use crate::config::LogFormat;

pub fn init(format: LogFormat) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| "info,tower_http=info,sqlx=warn".into());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        // A line that cannot be written (stderr sent to a full disk) is lost, not reported:
        // the subscriber reports it with `eprintln!`, which panics when stderr fails, so every
        // request then died mid-answer and the site form's uploads got no answer at all.
        .log_internal_errors(false);
    // A second initialisation (a test calling twice) keeps the first subscriber.
    let _ = match format {
        LogFormat::Text => builder.try_init(),
        LogFormat::Json => builder.json().try_init(),
    };
}
