//! Served datasets by the name a request gives. A name that is not served is the first thing
//! a newcomer gets wrong (`tless` on a server that serves other datasets, or a file named for
//! another one), so the answer lists what is served and says where the name was read.

use crate::app::App;
use crate::error::{AppError, AppResult};
use crate::store::datasets::DatasetRow;

/// The served dataset `name`, read from `from` ("the field `dataset`", "the file name ...");
/// 400 naming the served datasets otherwise.
pub async fn served(app: &App, name: &str, from: &str) -> AppResult<DatasetRow> {
    if let Some(row) = app.store.dataset_by_name(name).await? {
        return Ok(row);
    }
    let served = app.store.datasets().await?;
    Err(AppError::BadRequest(unknown(name, from, &served)))
}

/// "unknown dataset `tless` (from the field `dataset`): this server serves lmo, ycbv".
pub fn unknown(name: &str, from: &str, served: &[DatasetRow]) -> String {
    let names: Vec<&str> = served.iter().map(|d| d.name.as_str()).collect();
    let serves = match names.as_slice() {
        [] => "this server serves no dataset yet".to_string(),
        names => format!("this server serves {}", names.join(", ")),
    };
    format!("unknown dataset `{name}` (from {from}): {serves}")
}
