//! The fields of an upload as the browser form and the REST API send them (one multipart
//! body), with the limits that bound what reading one may take. Here rather than in the web
//! layer that reads the body so that the fuzz targets fill them from fuzzed bodies as the
//! server does; the web layer turns them into the submissions service's `Upload`.

/// Longest accepted text field (method description and the like).
pub const MAX_TEXT_FIELD: usize = 10_000;

/// Most result files in one upload: one per dataset, and BOP has fewer than twenty.
pub const MAX_FILES: usize = 20;

/// The fields of an upload as sent.
#[derive(Debug, Default)]
pub struct UploadFields {
    pub method: String,
    /// The team whose method it is, empty for the uploader's own.
    pub team: String,
    pub dataset: String,
    pub protocol: String,
    pub description: String,
    pub paper_url: String,
    pub code_url: String,
    pub training_data: String,
    pub modality: String,
    pub onboarding: String,
    pub objects: String,
    pub hardware: String,
    /// `true`: the method is under double-blind review; empty leaves it as it is.
    pub anonymous: String,
    pub visibility: String,
    /// The form's "publish when evaluated" box (sent only when ticked); the API reads
    /// `visibility` instead.
    pub publish: String,
    /// The CSRF token of a browser form (the API authenticates by token instead).
    pub csrf: String,
}

impl UploadFields {
    /// The text field a multipart field of this name fills; `None` for the files (`file`)
    /// and for names the upload does not know, which are drained and ignored.
    pub fn slot(&mut self, name: &str) -> Option<&mut String> {
        Some(match name {
            "method" => &mut self.method,
            "team" => &mut self.team,
            "dataset" => &mut self.dataset,
            "protocol" => &mut self.protocol,
            "description" => &mut self.description,
            "paper_url" => &mut self.paper_url,
            "code_url" => &mut self.code_url,
            "training_data" => &mut self.training_data,
            "modality" => &mut self.modality,
            "onboarding" => &mut self.onboarding,
            "objects" => &mut self.objects,
            "hardware" => &mut self.hardware,
            "anonymous" => &mut self.anonymous,
            "visibility" => &mut self.visibility,
            "publish" => &mut self.publish,
            "csrf" => &mut self.csrf,
            _ => return None,
        })
    }
}

/// The name a file is shown under: the last path component of the client's name (browsers
/// on Windows send whole paths), without control characters, at most 200 characters.
pub fn client_file_name(sent: Option<&str>) -> String {
    sent.unwrap_or("results.csv")
        .rsplit(['/', '\\'])
        .next()
        .unwrap_or("results.csv")
        .chars()
        .filter(|c| !c.is_control())
        .take(200)
        .collect()
}
