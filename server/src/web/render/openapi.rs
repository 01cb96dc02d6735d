//! The OpenAPI 3.1 description of `/api/v1`, served at `/api/v1/openapi.json` and shown as the
//! HTML page `/docs/api`, both from [`document`], so the two cannot disagree.

use serde_json::{Value, json};

/// The description, with the error answers every operation shares (see [`with_error_answers`]).
pub fn document() -> Value {
    with_error_answers(paths())
}

/// The document without the shared error answers.
fn paths() -> Value {
    let id_param =
        json!({ "name": "id", "in": "path", "required": true, "schema": { "type": "integer" } });
    let export_params = json!([
        { "name": "protocol", "in": "path", "required": true, "schema": { "type": "string", "enum": ["bop19", "eccv18", "bop24", "bop22-det", "bop22-seg"] } },
        { "name": "dataset", "in": "query", "schema": { "type": "string" }, "description": "one dataset, with per-object scores" },
        { "name": "sort", "in": "query", "schema": { "type": "string" }, "description": "average (default), time, method, or a dataset name" },
        { "name": "training", "in": "query", "schema": { "type": "string", "enum": ["synthetic", "real", "both"] } },
        { "name": "modality", "in": "query", "schema": { "type": "string", "enum": ["rgb", "depth", "rgb-d"] } }
    ]);
    let mut doc = json!({
        "openapi": "3.1.0",
        "info": {
            "title": "poseboard API",
            "version": env!("CARGO_PKG_VERSION"),
            "description": "Evaluation and leaderboards of the BOP 6D object pose benchmark. Scores use bop_toolkit's key names."
        },
        "components": {
            "securitySchemes": { "bearer": { "type": "http", "scheme": "bearer", "description": "a personal API token from /account" } },
            "schemas": {
                "Error": error_schema(),
                "VisibilityChange": { "type": "object", "required": ["visibility"], "properties": {
                    "visibility": { "type": "string", "enum": ["public", "private"] },
                    "confirm": { "type": "boolean", "default": false, "description": "publish despite red flags" } } }
            }
        },
        "paths": {
            "/api/v1/datasets": { "get": { "summary": "Datasets served, each with how far every evaluating host has prepared it", "responses": { "200": { "description": "{datasets: [{id, name, objects_count, scenes_count, images_count, targets_count, instances_count, image_width, image_height, added_at, retired, prepared}]}; prepared: one per host and prepared folder, {host, folder, state (preparing, ready, failed), images_done, images_total (0 while not counted), detail (why it failed, or what a preparation under way waits for; else null), updated_at}" } } } },
            "/api/v1/methods": { "get": { "summary": "Methods with public submissions", "responses": { "200": { "description": "{methods: [...]}" } } } },
            "/api/v1/submissions/{id}/pin": { "post": { "summary": "Make this submission its method's entry on its dataset (for every protocol it is scored under) instead of the best one; its owner or an administrator",
                "security": [{ "bearer": [] }], "parameters": [id_param],
                "responses": { "200": { "description": "{ok, submission, pinned: true}" }, "401": { "description": "no valid API token" }, "403": { "description": "another account's submission" }, "404": { "description": "no such submission" } } } },
            "/api/v1/submissions/{id}/unpin": { "post": { "summary": "Remove this submission's pin: the method's best public finished submission on the dataset is its entry again",
                "security": [{ "bearer": [] }], "parameters": [id_param],
                "responses": { "200": { "description": "{ok, submission, pinned: false}" }, "401": { "description": "no valid API token" }, "403": { "description": "another account's submission" }, "404": { "description": "no such submission" } } } },
            "/api/v1/admin/datasets/{name}/core": { "post": { "summary": "Make a dataset core (a column of the main leaderboards, counted in their average) or not; administrators only",
                "security": [{ "bearer": [] }],
                "parameters": [{ "name": "name", "in": "path", "required": true, "schema": { "type": "string" } }],
                "requestBody": { "required": true, "content": { "application/json": { "schema": { "type": "object", "required": ["core"], "properties": { "core": { "type": "boolean" } } } } } },
                "responses": { "200": { "description": "{ok, dataset, core}" }, "404": { "description": "no such served dataset, or not an administrator" } } } },
            "/api/v1/submissions/{id}": {
                "get": { "summary": "Status, progress (work_done of work estimate evaluations, progress_text and eta_seconds from the speed measured on this server, the queue place; while no evaluation worker runs, no_worker is true, eta_seconds null and progress_text says so), publication state, pre-flight report (red_flags, estimates_evaluated, estimated_seconds) and, once done, the scores per protocol; for its owner also `owner` with the download and action links",
                    "parameters": [id_param], "responses": { "200": { "description": "the submission" }, "404": { "description": "no such submission, or a private one of another account" } } },
                "delete": { "summary": "Delete a submission with its file, scores and errors (owner or administrator)", "security": [{ "bearer": [] }],
                    "parameters": [id_param], "responses": { "200": { "description": "{ok, deleted}" }, "401": { "description": "no valid API token" }, "404": { "description": "no such submission of yours" } } } },
            "/api/v1/submissions/{id}/visibility": { "post": { "summary": "Publish or withdraw a submission (owner or administrator); the boards change at once",
                "security": [{ "bearer": [] }], "parameters": [id_param],
                "requestBody": { "required": true, "content": {
                    "application/x-www-form-urlencoded": { "schema": { "$ref": "#/components/schemas/VisibilityChange" } },
                    "multipart/form-data": { "schema": { "$ref": "#/components/schemas/VisibilityChange" } },
                    "application/json": { "schema": { "$ref": "#/components/schemas/VisibilityChange" } } } },
                "responses": { "200": { "description": "{id, visibility, held, publication}" }, "400": { "description": "visibility is not public or private" },
                    "401": { "description": "no valid API token" }, "404": { "description": "no such submission of yours" },
                    "409": { "description": "red flags hold publication back: {error} names them; send confirm=true to publish anyway" } } } },
            "/api/v1/submissions/{id}/file": { "get": { "summary": "The uploaded result file, as sent (owner or administrator)", "security": [{ "bearer": [] }], "parameters": [id_param],
                "responses": { "200": { "description": "text/csv" }, "404": { "description": "no such submission of yours" } } } },
            "/api/v1/submissions/{id}/report": { "get": { "summary": "The JSON reports, one per protocol or the 2D task's (keys as `poseboard eval --out` writes them)", "parameters": [id_param],
                "responses": { "200": { "description": "{bop19: {...}, eccv18: {...}}" }, "404": { "description": "no such submission, or a private one of another account" } } } },
            "/api/v1/submissions/{id}/errors/{protocol}": { "get": { "summary": "Every evaluated estimate's errors against each ground-truth instance (the layout of `poseboard eval --errors-out`), owner or administrator",
                "security": [{ "bearer": [] }], "parameters": [id_param, { "name": "protocol", "in": "path", "required": true, "schema": { "type": "string", "enum": ["bop19", "eccv18"] } }],
                "responses": { "200": { "description": "[{scene_id, im_id, obj_id, est_id, score, gt_ids, errors: {signature: [error per gt]}}]" }, "404": { "description": "no such submission of yours, or not evaluated under that protocol" } } } },
        }
    });
    // One `json!` holding every path overflows the macro's recursion limit: the rest here.
    let more = json!({
            "/api/v1/submissions": {
                "get": { "summary": "The public finished submissions, newest first (see below)" },
                "post": {
                    "summary": "Upload result files (BOP'19 CSV, or BOP'22 2D JSON; one per dataset) for evaluation",
                    "security": [{ "bearer": [] }],
                    "requestBody": { "required": true, "content": { "multipart/form-data": { "schema": {
                        "type": "object", "required": ["method", "file"],
                        "properties": {
                            "method": { "type": "string", "maxLength": 100 },
                            "dataset": { "type": "string", "description": "default: the dataset of the file name METHOD_DATASET-SPLIT.csv; must agree with it" },
                            "protocol": { "type": "string", "enum": ["bop19", "eccv18", "bop19,eccv18", "bop24", "bop22-det", "bop22-seg"], "description": "default: a CSV file is scored under bop19 and eccv18, its pre-flight warning about bop19's selection only (`bop19,eccv18` for both's); bop24: a CSV file scored for 6D detection (average precision on the images of the dataset's test_targets_bop24.json, the toolkit's cap of estimates per image; 400 naming the file when the dataset has none); for a .json file (BOP'22 2D results) the task its content shows: bop22-seg when an entry has a `segmentation`, else bop22-det (amodal boxes)" },
                            "description": { "type": "string" },
                            "paper_url": { "type": "string" },
                            "code_url": { "type": "string" },
                            "training_data": { "type": "string", "enum": ["synthetic", "real", "both"] },
                            "modality": { "type": "string", "enum": ["rgb", "depth", "rgb-d"] },
                            "objects": { "type": "string", "enum": ["seen", "unseen"] },
                            "onboarding": { "type": "string", "enum": ["model-based", "model-free"] },
                            "hardware": { "type": "string", "maxLength": 200, "description": "what the reported times were measured on" },
                            "visibility": { "type": "string", "enum": ["public", "private"], "description": "default: private (only its owner and the administrators see it; everyone else gets 404). public: published once evaluated, unless the pre-flight raises red flags (translations in metres, more than half of the targets without an estimate, estimates for objects the dataset lacks): then it stays private, `held`, until its owner confirms (POST .../visibility with confirm=true). Anything else is 400. For a file already submitted for this method (same dataset and protocols), the visibility given becomes that submission's; without the field it keeps its own" },
                            "file": { "type": "array", "items": { "type": "string", "format": "binary" }, "maxItems": 20, "description": "one or several result files, one per dataset, or a .zip of them (unpacked, within the upload limit); each result file becomes a submission" }
                        } } } } },
                    "responses": {
                        "202": { "description": "queued: {submissions: [{id, submission, preflight, url}]}, and with one file also its fields at the top level" },
                        "401": { "description": "no valid API token (Authorization: Bearer TOKEN)" },
                        "200": { "description": "every file was already submitted for this method (same dataset and protocols): the existing submissions, not evaluated again, with the visibility asked for if one was given" },
                        "408": { "description": "the upload stalled: its body must keep delivering a minimum (by default 64 KiB every 20 s), however long the whole upload takes" },
                        "400": { "description": "a missing or bad field" },
                        "413": { "description": "the upload is larger than the limit (the message states it): {error, limit_bytes}" },
                        "422": { "description": "a file is not a valid result file, or is named for another dataset than the field says, or a zip holds other entries than result files, unpacks beyond the upload limit or holds too many entries; nothing is submitted: {error, problems: [{file, line, message}]}" },
                        "429": { "description": "over the fair-use limit of submissions per dataset (the message states it and when the next is allowed, as a UTC date and time): nothing of the upload is submitted; {error, retry_at}, and a Retry-After header" },
                        "507": { "description": "the service's disk (its data directory's or its database's) is full: nothing of the upload was stored (no submission, no file); {error}" }
                    }
                }
            },
            "/api/v1/methods/{id}": {
                "get": { "summary": "A method (with its owner's name: its team's for a team's method, also given as `team`) and its public submissions (a team's members see its private ones too)", "parameters": [id_param],
                    "responses": { "200": { "description": "{method, submissions}" }, "404": { "description": "no such public method" } } },
                "post": { "summary": "Change a method's details (its owner, any member of a team's method's team, or an administrator); fields left out keep their values, an empty one clears it",
                    "security": [{ "bearer": [] }], "parameters": [id_param],
                    "requestBody": { "required": true, "content": { "application/json": { "schema": {
                        "type": "object",
                        "properties": {
                            "description": { "type": "string", "maxLength": 10000 },
                            "authors": { "type": "string", "maxLength": 1000 },
                            "year": { "type": ["integer", "string"], "description": "1900 to 2100, or empty" },
                            "paper_url": { "type": "string", "description": "an http(s) link" },
                            "code_url": { "type": "string", "description": "an http(s) link" },
                            "training_data": { "type": "string", "enum": ["synthetic", "real", "both", ""] },
                            "detection_modality": { "type": "string", "enum": ["rgb", "depth", "rgb-d", ""], "description": "input of the detection stage" },
                            "modality": { "type": "string", "enum": ["rgb", "depth", "rgb-d", ""], "description": "input of the pose stage" },
                            "refinement": { "type": "string", "maxLength": 1000 },
                            "detections": { "type": "string", "maxLength": 1000, "description": "the detections the method starts from" },
                            "model_scope": { "type": "string", "enum": ["all", "per-object", ""], "description": "one model for all objects or one per object" },
                            "hardware": { "type": "string", "maxLength": 200, "description": "what the reported times were measured on" },
                            "objects": { "type": "string", "enum": ["seen", "unseen", ""], "description": "seen: trained on images of the test objects; unseen: onboarded at test time" },
                            "onboarding": { "type": "string", "enum": ["model-based", "model-free", ""], "description": "how the test objects are onboarded: from their 3D models or from reference images" }
                        } } } } },
                    "responses": { "200": { "description": "{method}: as stored" }, "400": { "description": "a field that does not parse" }, "401": { "description": "no valid API token" },
                        "403": { "description": "the method is another account's" }, "404": { "description": "no such method, or another account's private one" } } }
            },
            "/api/v1/leaderboards/{protocol}": { "get": { "summary": "The leaderboard of a protocol or task (bop24: ranked by bop24_mAP, every cell's `stats` its parts; bop22-det, bop22-seg: ranked by AP, the average over the core datasets being AP_C; with a dataset, every cell has the twelve AP/AR `stats`)",
                "parameters": [
                    { "name": "protocol", "in": "path", "required": true, "schema": { "type": "string", "enum": ["bop19", "eccv18", "bop24", "bop22-det", "bop22-seg"] } },
                    { "name": "dataset", "in": "query", "schema": { "type": "string" }, "description": "one dataset, with per-object scores" },
                    { "name": "sort", "in": "query", "schema": { "type": "string" }, "description": "average (default), time, method, or a dataset name" },
                    { "name": "training", "in": "query", "schema": { "type": "string", "enum": ["synthetic", "real", "both"] } },
                    { "name": "modality", "in": "query", "schema": { "type": "string", "enum": ["rgb", "depth", "rgb-d"] } },
                    { "name": "objects", "in": "query", "schema": { "type": "string", "enum": ["seen", "unseen"] }, "description": "only methods of this category, ranked among themselves; a method that does not say is left out" },
                    { "name": "onboarding", "in": "query", "schema": { "type": "string", "enum": ["model-based", "model-free"] }, "description": "only methods of this category, ranked among themselves; a method that does not say is left out" },
                    { "name": "group", "in": "query", "schema": { "type": "string" }, "description": "the group of datasets ranked over (GET /api/v1/groups); default: core, the core datasets" },
                    { "name": "curves", "in": "query", "schema": { "type": "string" }, "description": "the page's query for the methods its charts overlay (method ids separated by commas, at most 5); checked here, the JSON is the same with or without it" }
                ],
                "responses": { "200": { "description": "{protocol, parameters, datasets, group, groups, core (the group's datasets served here), columns, sorted_by, rows}. Each row: rank (null when the method lacks a score on a dataset shown; equal scores at the precision shown share a rank), method, method_id, owner, average (over the columns; null when unranked), mean (over the columns covered), covered, ci95 ([low, high]: bootstrap 95 % interval of the average, from 1000 seeded resamplings of each dataset's images, replicate-wise means over the datasets), scores per dataset ({submission_id, score, ..., pinned, ci95}), time (mean over the same datasets, per image for bop19 and per target for eccv18), hardware. Rows: ranked by rank, then the unranked by coverage and mean; `sort` reorders them and keeps each rank" }, "400": { "description": "an unknown sort, filter value or malformed curves" }, "404": { "description": "unknown protocol, dataset or group" } } } },
            "/api/v1/groups": { "get": { "summary": "The groups of datasets a board ranks over (`?group=NAME`): the default group `core` (the core datasets) first, then the stored ones, each with the datasets it names and those served here",
                "responses": { "200": { "description": "{groups: [{name, default, datasets, served}]}" } } } },
            "/api/v1/admin/groups": { "post": { "summary": "Create a group of datasets, or replace the datasets of the group of that name; administrators only (audited). Datasets are folder names, served or not; the default group `core` takes served ones only (it sets the core datasets)",
                "security": [{ "bearer": [] }],
                "requestBody": { "required": true, "content": { "application/json": { "schema": { "type": "object", "required": ["name", "datasets"], "properties": {
                    "name": { "type": "string", "maxLength": 60, "description": "letters, digits, -, _ and ." },
                    "datasets": { "type": "array", "items": { "type": "string" }, "minItems": 1, "maxItems": 100 } } } } } },
                "responses": { "201": { "description": "created: {group, created: true}" }, "200": { "description": "replaced: {group, created: false}" }, "400": { "description": "a bad name or dataset name, no dataset, or `core` with a dataset not served" }, "404": { "description": "not an administrator" } } } },
            "/api/v1/admin/groups/{name}": { "delete": { "summary": "Delete a group of datasets (not the default one); administrators only (audited)",
                "security": [{ "bearer": [] }],
                "parameters": [{ "name": "name", "in": "path", "required": true, "schema": { "type": "string" } }],
                "responses": { "200": { "description": "{ok, deleted}" }, "400": { "description": "the default group" }, "404": { "description": "no such group, or not an administrator" } } } },
            "/api/v1/compare": { "get": { "summary": "Two finished submissions on one dataset side by side: scores per protocol, per object and per visibility bin, and target by target (scene, image, object) where one found more instances than the other, with both errors and paired counts. Two 2D submissions of one task compare image by image and category; two bop24 submissions image by image (their mAPs, and per target image each one's counted instances, true and false positives, ignored and missed estimates at `error` and `threshold`). Each must be visible to the caller",
                "parameters": [
                    { "name": "a", "in": "query", "required": true, "schema": { "type": "integer" } },
                    { "name": "b", "in": "query", "required": true, "schema": { "type": "integer" } },
                    { "name": "protocol", "in": "query", "schema": { "type": "string", "enum": ["eccv18", "bop19"] }, "description": "whose outcomes are paired; default eccv18 when both have it" },
                    { "name": "error", "in": "query", "schema": { "type": "string" }, "description": "the error deciding correctness (vsd, mssd, mspd); default vsd. bop24: mssd (x diameter), mssd_mm or mspd (px at 640 px width); default mssd" },
                    { "name": "tau", "in": "query", "schema": { "type": "number" }, "description": "VSD only: one of the protocol's taus; default its main tau" },
                    { "name": "threshold", "in": "query", "schema": { "type": "number" }, "description": "default: VSD's main theta, another error's middle threshold. bop24: one of the error's ten thresholds (mssd 0.05..0.5, mssd_mm 2..20, mspd 5..50), default the middle (0.3, 12, 30)" }],
                "responses": { "200": { "description": "{dataset, a, b, scores: [{protocol, scores, objects, visibility}], protocol, criterion, counts: {instances, both, only_a, only_b, neither}, targets: [{scene_id, im_id, obj_id, instances, a: {found, error, url}, b}]}; bop24: {dataset, a, b, task, scores: [{name, unit, a, b}], criterion: {error, threshold, description, thresholds, unit}, a_total, b_total, images: [{scene_id, im_id, a, b, a_url, b_url}]}, each count {counted, true_positives, false_positives, ignored, missed, beyond_cap, object_absent}" },
                    "400": { "description": "a or b missing, not finished, on different datasets, or an unknown criterion" }, "404": { "description": "no such submission, or another account's private one" } } } },
            "/api/v1/submissions/{id}/targets": { "get": { "summary": "A finished submission's worst target instances per object (missed first, then by decreasing error), at the criterion of /api/v1/compare; for a bop24 submission its target images, the most mistakes (missed plus false positives) first, with their counts at `error` and `threshold`",
                "parameters": [id_param,
                    { "name": "protocol", "in": "query", "schema": { "type": "string", "enum": ["eccv18", "bop19"] } },
                    { "name": "error", "in": "query", "schema": { "type": "string" } },
                    { "name": "tau", "in": "query", "schema": { "type": "number" } },
                    { "name": "threshold", "in": "query", "schema": { "type": "number" } }],
                "responses": { "200": { "description": "{submission, protocol, criterion, order, objects: [{obj_id, instances, correct, worst: [{scene_id, im_id, obj_id, gt_id, visib_fract, estimates, est_id, error, correct, url, image_url}]}]}; bop24: {submission, task, criterion, map, max_estimates_per_image, totals, objects: [{obj_id, counts..., ap}], order, images: [{scene_id, im_id, counted, true_positives, false_positives, ignored, missed, beyond_cap, object_absent, url}]}" },
                    "400": { "description": "not finished, or an unknown criterion" } } } },
            "/api/v1/submissions/{id}/targets/{scene}/{im}": { "get": { "summary": "One target image of a finished bop24 submission: every estimate of the image (line in the file, object, score, verdict: true_positive, false_positive, ignored, beyond_cap or object_absent; the instance taken, else the nearest, and the error against it) and every ground-truth instance with the estimate that took it, at `error` and `threshold` as in /api/v1/compare",
                "parameters": [id_param,
                    { "name": "scene", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "im", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "error", "in": "query", "schema": { "type": "string", "enum": ["mssd", "mssd_mm", "mspd"] } },
                    { "name": "threshold", "in": "query", "schema": { "type": "number" } }],
                "responses": { "200": { "description": "{submission, scene_id, im_id, criterion, tally, instances: [{gt_id, obj_id, visib_fract, counted, matched_by}], estimates: [{line, obj_id, score, verdict, gt_id, error}], gallery_url}" },
                    "400": { "description": "not finished, or an unknown error or threshold (the message lists the error's thresholds)" }, "404": { "description": "no such submission or target image, another account's private submission, or not a bop24 submission (the answer says where its targets are)" } } } },
            "/api/v1/submissions/{id}/errors/{protocol}/{scene}/{im}/{obj}": { "get": { "summary": "One target of a finished submission: its evaluated estimates' errors against each ground-truth instance of the object, and which instances counted as correct at the chosen criterion and at each error's default",
                "parameters": [id_param, { "name": "protocol", "in": "path", "required": true, "schema": { "type": "string", "enum": ["bop19", "eccv18"] } },
                    { "name": "scene", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "im", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "obj", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "error", "in": "query", "schema": { "type": "string" } },
                    { "name": "tau", "in": "query", "schema": { "type": "number" } },
                    { "name": "threshold", "in": "query", "schema": { "type": "number" } }],
                "responses": { "200": { "description": "{submission, scene_id, im_id, obj_id, protocol, columns: [{signature, label}], estimates: [{est_id, score, against: [{gt_id, errors}]}], verdicts: [{criterion, outcomes, not_counted: [{gt_id, visib_fract, reason}] (the instances of the object in the image the recall leaves out, and why)}], image_url}" },
                    "400": { "description": "not finished, or an unknown criterion" }, "404": { "description": "no such submission or target, or another account's private submission" } } } },
            "/api/v1/me/submissions": { "get": { "summary": "Your submissions, private ones included, newest first, with status, publication state, headline scores, download and action links",
                "security": [{ "bearer": [] }], "responses": { "200": { "description": "{submissions: [...]}" }, "401": { "description": "no valid API token or session" } } } },
            "/api/v1/me/quota": { "get": { "summary": "How many submissions you have left on a dataset under the fair-use limit (the number the upload form shows), and when the next one is allowed when none is left",
                "security": [{ "bearer": [] }],
                "parameters": [{ "name": "dataset", "in": "query", "required": true, "schema": { "type": "string" }, "description": "a served dataset's name" }],
                "responses": { "200": { "description": "{dataset, limit (null: no limit), window_secs, used, left (null: no limit), next_at (epoch ms, when none is left), next_at_utc (the same as \"2026-12-04 17:20 UTC\"), summary (in words, as the upload form and the CLI say it)}" },
                    "400": { "description": "no or an unknown dataset (the message lists the served ones)" }, "401": { "description": "no valid API token or session" } } } },
            "/api/v1/submissions/{id}/targets/{scene_id}/{im_id}/{obj_id}.png": { "get": { "summary": "A target seen through a submission: the test image (RGB, else gray, else the depth image) with the object's ground-truth silhouettes (green tint, green outline) and the silhouettes of the submission's estimates its evaluation considered (the first n_top by score; magenta tint, magenta outline, drawn on top), rendered by the evaluator's renderer",
                "parameters": [id_param,
                    { "name": "scene_id", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "im_id", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "obj_id", "in": "path", "required": true, "schema": { "type": "integer" } },
                    { "name": "protocol", "in": "query", "schema": { "type": "string", "enum": ["bop19", "eccv18"] }, "description": "whose n_top decides the estimates drawn; the submission's first protocol by default" },
                    { "name": "crop", "in": "query", "schema": { "type": "string", "enum": ["object"] }, "description": "`object`: the picture cut to the object (its ground-truth silhouettes, else the estimates', with a margin of a quarter of the box, at least 16 px), as the targets page's gallery shows it" }],
                "responses": { "200": { "description": "image/png" }, "400": { "description": "a crop other than `object`" }, "404": { "description": "no such submission (or a private one of another account), no such test target of its dataset, or a protocol it was not submitted for" } } } },
            "/leaderboards/{protocol}/export.csv": { "get": { "summary": "Every row of a leaderboard as CSV (a download): rank, method, owner, training data, input, hardware; per dataset shown its score, the breakdowns, time, submission and the score's reproducibility record (evaluator version, protocol, parameters as JSON, dataset content hash, result file SHA-256); average, mean, covered, time; per object with `dataset`. Scores as fractions",
                "parameters": export_params.clone(),
                "responses": { "200": { "description": "text/csv" }, "400": { "description": "an unknown sort or filter value" }, "404": { "description": "unknown protocol or dataset" } } } },
            "/leaderboards/{protocol}/export.json": { "get": { "summary": "Every row of a leaderboard as JSON (a download): {protocol, score_name, time_unit, parameters, dataset, columns, rows}; the rows are those of /api/v1/leaderboards/{protocol}, each score with its `record`",
                "parameters": export_params.clone(),
                "responses": { "200": { "description": "application/json" }, "400": { "description": "an unknown sort or filter value" }, "404": { "description": "unknown protocol or dataset" } } } },
            "/leaderboards/{protocol}/export.tex": { "get": { "summary": "A leaderboard as a complete LaTeX `tabular` in the ECCV'18 paper's layout (needs booktabs): methods by rows; the datasets (with `dataset`: the objects, then the dataset), the average and the time as columns, scores in %, the best of each column in bold; the reproducibility records follow as comment lines",
                "parameters": export_params,
                "responses": { "200": { "description": "application/x-tex" }, "400": { "description": "an unknown sort or filter value" }, "404": { "description": "unknown protocol or dataset" } } } },
            "/api/v1/rescoring": { "get": { "summary": "Every score that re-scoring by a newer evaluator changed, newest first (private submissions' only to their owners and administrators)",
                "responses": { "200": { "description": "{evaluator_version, changes: [{submission_id, method, dataset, protocol, key (score, recall, ar_vsd, ar_mssd, ar_mspd, time, obj_N), before, after, old_version, new_version, changed_at (epoch ms)}]}" } } } },
            "/api/v1/snapshots": { "get": { "summary": "Dated snapshots of the leaderboards, newest first",
                "responses": { "200": { "description": "{snapshots: [{id, taken_at (epoch ms), taken_by, url, boards: [{protocol, dataset (empty: all datasets), url, json_url}]}]}" } } } },
            "/api/v1/snapshots/{id}": { "get": { "summary": "One board of a snapshot: the bytes the leaderboard's JSON served when the snapshot was taken, unchanged since",
                "parameters": [
                    id_param,
                    { "name": "protocol", "in": "query", "schema": { "type": "string", "enum": ["bop19", "eccv18", "bop24", "bop22-det", "bop22-seg"] }, "description": "default: bop19" },
                    { "name": "dataset", "in": "query", "schema": { "type": "string" }, "description": "one dataset's board; default: all datasets" }
                ],
                "responses": { "200": { "description": "the body /api/v1/leaderboards/{protocol} answered then" }, "404": { "description": "no such snapshot or board" } } } },
            "/api/v1/admin/snapshots": { "post": { "summary": "Take a snapshot of every board now (administrators; to anyone else this route does not exist)",
                "security": [{ "bearer": [] }],
                "responses": { "201": { "description": "{id, taken_at, taken_by, url, boards: [...]} as listed by /api/v1/snapshots" }, "404": { "description": "not an administrator" } } } },
            "/api/v1/openapi.json": { "get": { "summary": "This document", "responses": { "200": { "description": "OpenAPI 3.1" } } } }
    });
    let review = json!({
            "/api/v1/methods/{id}/reveal": { "post": { "summary": "End a method's double-blind review (its owner or an administrator): every live page, board and list names the owner again, with the authors and links; snapshots taken meanwhile stay anonymous",
                "security": [{ "bearer": [] }], "parameters": [id_param],
                "responses": { "200": { "description": "{method}" }, "403": { "description": "not the method's owner" }, "404": { "description": "no such method the caller may see" } } } }
    });
    for more in [more, review] {
        if let (Some(paths), Value::Object(more)) = (doc["paths"].as_object_mut(), more) {
            paths.extend(more);
        }
    }
    // Set apart: one `json!` of the whole document would pass the macro's recursion limit.
    let anonymous = "true: under double-blind review; everyone but the owner and the administrators sees `anonymous` as its owner, without authors, paper or code links, on every page, board, export, snapshot and feed";
    let fields = [
        (
            "/paths/~1api~1v1~1methods~1{id}/post/requestBody/content/application~1json/schema/properties",
            json!({ "type": ["boolean", "string"], "description": anonymous }),
        ),
        (
            "/paths/~1api~1v1~1submissions/post/requestBody/content/multipart~1form-data/schema/properties",
            json!({ "type": "string", "enum": ["true", "false"], "description": format!("{anonymous}; left out, the method stays as it is") }),
        ),
    ];
    for (at, field) in fields {
        if let Some(Value::Object(properties)) = doc.pointer_mut(at) {
            properties.insert("anonymous".into(), field);
        }
    }
    if let Some(get) = doc.pointer_mut("/paths/~1api~1v1~1submissions/get") {
        *get = json!({ "summary": "The public finished submissions, newest first, 50 a page (the page /submissions; the newest page as Atom at /submissions.atom)",
                    "parameters": [{ "name": "page", "in": "query", "schema": { "type": "integer", "minimum": 1, "maximum": 100000 } }],
                    "responses": { "200": { "description": "{page, per_page, more, newer, older (page numbers or null), feed, submissions: [{id, created_at, finished_at, method_id, method, dataset, task, owner (`anonymous` for a method under double-blind review), score: {board, name, value} or null}]}" }, "400": { "description": "a page that is no number from 1 to 100000" } } });
    }
    if let (Some(paths), Value::Object(teams)) = (doc["paths"].as_object_mut(), teams()) {
        paths.extend(teams);
    }
    if let (Some(paths), Value::Object(challenges)) = (doc["paths"].as_object_mut(), challenges()) {
        paths.extend(challenges);
    }
    // Here rather than with the upload's other fields, for the same recursion limit.
    let upload = "/paths/~1api~1v1~1submissions/post/requestBody/content/multipart~1form-data/schema/properties";
    if let Some(Value::Object(fields)) = doc.pointer_mut(upload) {
        fields.insert(
            "team".into(),
            json!({ "type": "string", "maxLength": 40, "description": "a team of yours: the files are for the team's method of that name (created as the team's if new), which every member submits to and edits and the boards show under the team's name; each submission still counts against your own fair-use limit. A team you are not a member of (or none of that name) is 404: team `NAME` is not one of your teams" }),
        );
    }
    doc
}

/// The team routes (see `crate::service::teams`).
fn teams() -> Value {
    let name_param = json!({ "name": "name", "in": "path", "required": true, "schema": { "type": "string" }, "description": "the team's name" });
    let user_param = json!({ "name": "user", "in": "path", "required": true, "schema": { "type": "string" }, "description": "the member's account name" });
    let not_yours = json!({ "description": "no team of that name that you are a member of: {error} says team `NAME` is not one of your teams" });
    json!({
        "/api/v1/teams": { "post": { "summary": "Create a team: you are its creator and first member. Its name (1 to 40 letters, digits, `-`, `_`, `.`) is shown as the owner of its methods",
            "security": [{ "bearer": [] }],
            "requestBody": { "required": true, "content": { "application/json": { "schema": { "type": "object", "required": ["name"], "properties": { "name": { "type": "string", "maxLength": 40 } } } } } },
            "responses": { "201": { "description": "{team: {name, creator, created_at}, url}" }, "400": { "description": "a name that does not parse" }, "409": { "description": "a team of that name exists" } } } },
        "/api/v1/teams/{name}": { "get": { "summary": "A team: its creator, members (name, joined_at) and methods (to members and administrators every one, to others those with a public submission), and whether you are a member (`member`) and may remove members (`may_remove`)",
            "parameters": [name_param.clone()],
            "responses": { "200": { "description": "{team, members, methods, member, may_remove}" }, "404": { "description": "no team of that name" } } } },
        "/api/v1/teams/{name}/invitations": { "post": { "summary": "Invite an account to the team (members only); it sees the invitation on its account page and joins by accepting. Inviting again keeps the first invitation",
            "security": [{ "bearer": [] }], "parameters": [name_param.clone()],
            "requestBody": { "required": true, "content": { "application/json": { "schema": { "type": "object", "required": ["user"], "properties": { "user": { "type": "string", "description": "the account's name" } } } } } },
            "responses": { "200": { "description": "{ok, team, invited}" }, "404": not_yours.clone(), "409": { "description": "the account is a member already" } } } },
        "/api/v1/teams/{name}/accept": { "post": { "summary": "Accept your invitation to the team: you become a member",
            "security": [{ "bearer": [] }], "parameters": [name_param.clone()],
            "responses": { "200": { "description": "{ok, team}" }, "404": { "description": "no invitation to that team waits for you" } } } },
        "/api/v1/teams/{name}/leave": { "post": { "summary": "Leave the team (written to the audit log): you can no longer submit to its methods, edit them or see their private submissions (your own uploads stay yours)",
            "security": [{ "bearer": [] }], "parameters": [name_param.clone()],
            "responses": { "200": { "description": "{ok, team, left}" }, "404": not_yours.clone() } } },
        "/api/v1/teams/{name}/members/{user}/remove": { "post": { "summary": "Remove a member from the team (its creator or an administrator; written to the audit log)",
            "security": [{ "bearer": [] }], "parameters": [name_param, user_param],
            "responses": { "200": { "description": "{ok, team, removed}" }, "403": { "description": "a member who did not create the team" }, "404": { "description": "not one of your teams, or the account is not a member" } } } }
    })
}

/// The challenge routes (see `crate::service::challenges`).
fn challenges() -> Value {
    let slug_param = json!({ "name": "slug", "in": "path", "required": true, "schema": { "type": "string" }, "description": "the challenge's slug" });
    json!({
        "/api/v1/challenges": { "get": { "summary": "Every challenge, the latest deadline first (the page /challenges)",
            "responses": { "200": { "description": "{challenges: [{slug, name, tasks, groups, objects, onboarding, deadline (epoch ms), deadline_utc (RFC 3339), closed, fast_seconds, awards, snapshot_id (null until taken), url, json_url}]}" } } } },
        "/api/v1/challenges/{slug}": { "get": { "summary": "A challenge (the page /challenges/{slug}): its fields as listed, its boards as they stand (each task over each group: {protocol, group, columns, url of the live board, rows: [{rank, method_id, method, owner, average, time, after_deadline}]}), `snapshot_id` and `snapshot_url` once the deadline's snapshot is taken, and `awards` decided on the boards at the deadline: [{task, award, title, rule, winner: {method_id, method, owner, average} or null, override: {note, by, at} or null}] (empty before the deadline)",
            "parameters": [slug_param.clone()],
            "responses": { "200": { "description": "the challenge" }, "404": { "description": "no challenge of that slug" } } } },
        "/api/v1/admin/challenges": { "post": { "summary": "Create a challenge (administrators; audited). At its deadline the service takes a snapshot of every board by itself, dated at the deadline (at the next start if no server runs then), once whatever the number of servers, and decides the awards",
            "security": [{ "bearer": [] }],
            "requestBody": { "required": true, "content": { "application/json": { "schema": { "type": "object", "required": ["slug", "name", "tasks", "deadline"], "properties": {
                "slug": { "type": "string", "maxLength": 60, "description": "lowercase letters, digits and `-`: its address /challenges/SLUG" },
                "name": { "type": "string", "maxLength": 200 },
                "tasks": { "type": "array", "items": { "type": "string", "enum": ["bop19", "eccv18", "bop24", "bop22-det", "bop22-seg"] } },
                "groups": { "type": "array", "items": { "type": "string" }, "description": "dataset groups (see /api/v1/groups); default: core. The awards are decided on the first" },
                "deadline": { "type": "string", "format": "date-time", "description": "RFC 3339 with its offset, in the future" },
                "objects": { "type": "string", "enum": ["", "seen", "unseen"], "description": "the categories filter of its boards" },
                "onboarding": { "type": "string", "enum": ["", "model-based", "model-free"] },
                "fast_seconds": { "type": "number", "exclusiveMinimum": 0, "default": 1, "description": "mean time per image under which a method is fast" },
                "awards": { "type": "array", "items": { "type": "string", "enum": ["overall", "rgb-only", "fast", "open-source", "single-model", "synthetic", "default-detections"] }, "description": "default: every award" } } } } } },
            "responses": { "201": { "description": "{challenge} as listed" }, "400": { "description": "a field that does not parse: {error} names it" }, "404": { "description": "not an administrator" }, "409": { "description": "a challenge of that slug exists" } } } },
        "/api/v1/admin/challenges/{slug}/awards": { "post": { "summary": "Override an award of a closed challenge (administrators; audited): the page shows the note next to the rule",
            "security": [{ "bearer": [] }], "parameters": [slug_param],
            "requestBody": { "required": true, "content": { "application/json": { "schema": { "type": "object", "required": ["task", "award", "note"], "properties": {
                "task": { "type": "string" }, "award": { "type": "string" },
                "method_id": { "type": ["integer", "null"], "description": "a method on the task's board at the deadline; null: not awarded" },
                "note": { "type": "string", "maxLength": 1000 } } } } } },
            "responses": { "200": { "description": "the challenge, as GET /api/v1/challenges/{slug}" }, "400": { "description": "a field that does not parse: {error} names it" }, "404": { "description": "no such challenge, or not an administrator" }, "409": { "description": "the deadline's snapshot is not taken yet" } } } }
    })
}

/// The body of every error answer (`crate::web::error::ErrorBody`).
fn error_schema() -> Value {
    json!({
        "type": "object",
        "required": ["error"],
        "properties": {
            "error": { "type": "string", "description": "what went wrong, in a sentence; for 413 and 429 it states the limit" },
            "problems": { "type": "array", "description": "422: every problem of the upload", "items": {
                "type": "object", "required": ["line", "message"],
                "properties": {
                    "file": { "type": "string", "description": "the file, when an upload holds several" },
                    "line": { "type": "integer", "description": "0: the file as a whole" },
                    "message": { "type": "string" }
                } } },
            "retry_at": { "type": "integer", "description": "429: when the next request is allowed, epoch milliseconds (also the Retry-After header, in seconds)" },
            "links": { "type": "array", "description": "404 of something a resource does not have (a 2D submission's targets): where to go instead", "items": {
                "type": "object", "required": ["label", "href"],
                "properties": { "label": { "type": "string" }, "href": { "type": "string" } } } },
            "limit_bytes": { "type": "integer", "description": "413: the largest upload accepted" }
        }
    })
}

/// Adds what every operation of its kind answers, unless it says so itself: 401 where a token
/// is needed, 404 where the path names something, 413 and 422 where a body is uploaded; and
/// gives every 4xx answer the error body's schema.
fn with_error_answers(mut doc: Value) -> Value {
    let Some(paths) = doc.get_mut("paths").and_then(Value::as_object_mut) else {
        return doc;
    };
    for (path, item) in paths.iter_mut() {
        let Some(operations) = item.as_object_mut() else {
            continue;
        };
        for op in operations.values_mut() {
            let secured = op.get("security").is_some();
            let uploads = op.get("requestBody").is_some();
            let Some(responses) = op.get_mut("responses").and_then(Value::as_object_mut) else {
                continue;
            };
            let mut add = |code: &str, description: &str| {
                responses
                    .entry(code)
                    .or_insert_with(|| json!({ "description": description }));
            };
            if secured {
                add("401", "no valid API token (Authorization: Bearer TOKEN)");
            }
            if path.contains('{') {
                add("404", "nothing of that name or id");
            }
            if uploads {
                add(
                    "413",
                    "the upload is larger than the limit (the message states it)",
                );
                add("422", "the upload cannot be evaluated: {error, problems}");
            }
            for (code, answer) in responses.iter_mut() {
                if code.starts_with('4')
                    && let Some(answer) = answer.as_object_mut()
                {
                    answer.entry("content").or_insert_with(error_content);
                }
            }
        }
    }
    doc
}

fn error_content() -> Value {
    json!({ "application/json": { "schema": { "$ref": "#/components/schemas/Error" } } })
}
