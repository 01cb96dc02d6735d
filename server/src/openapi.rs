//! The OpenAPI 3.1 description of `/api/v1`, served at `/api/v1/openapi.json`.

use serde_json::{Value, json};

pub fn document() -> Value {
    let id_param =
        json!({ "name": "id", "in": "path", "required": true, "schema": { "type": "integer" } });
    json!({
        "openapi": "3.1.0",
        "info": {
            "title": "poseboard API",
            "version": env!("CARGO_PKG_VERSION"),
            "description": "Evaluation and leaderboards of the BOP 6D object pose benchmark. Scores use bop_toolkit's key names."
        },
        "components": { "securitySchemes": { "bearer": { "type": "http", "scheme": "bearer", "description": "a personal API token from /account" } } },
        "paths": {
            "/api/v1/datasets": { "get": { "summary": "Datasets served", "responses": { "200": { "description": "{datasets: [...]}" } } } },
            "/api/v1/methods": { "get": { "summary": "Methods with public submissions", "responses": { "200": { "description": "{methods: [...]}" } } } },
            "/api/v1/methods/{id}": { "get": { "summary": "A method and its public submissions", "parameters": [id_param],
                "responses": { "200": { "description": "{method, submissions}" }, "404": { "description": "no such public method" } } } },
            "/api/v1/submissions": {
                "get": { "summary": "Recent public submissions", "responses": { "200": { "description": "{submissions: [...]}" } } },
                "post": {
                    "summary": "Upload result files (BOP'19 CSV, one per dataset) for evaluation",
                    "security": [{ "bearer": [] }],
                    "requestBody": { "required": true, "content": { "multipart/form-data": { "schema": {
                        "type": "object", "required": ["method", "file"],
                        "properties": {
                            "method": { "type": "string", "maxLength": 100 },
                            "dataset": { "type": "string", "description": "default: the dataset of the file name METHOD_DATASET-SPLIT.csv; must agree with it" },
                            "protocol": { "type": "string", "enum": ["bop19", "eccv18"], "description": "default: both" },
                            "description": { "type": "string" },
                            "paper_url": { "type": "string" },
                            "code_url": { "type": "string" },
                            "training_data": { "type": "string", "enum": ["synthetic", "real", "both"] },
                            "modality": { "type": "string", "enum": ["rgb", "depth", "rgb-d"] },
                            "hardware": { "type": "string", "maxLength": 200, "description": "what the reported times were measured on" },
                            "visibility": { "type": "string", "enum": ["public", "private"], "description": "default: public for a new submission. For a file already submitted for this method (same dataset and protocols), the visibility given becomes that submission's (re-sending a file is how to publish or withdraw it); without the field it keeps its own" },
                            "file": { "type": "array", "items": { "type": "string", "format": "binary" }, "maxItems": 20, "description": "one or several result files, one per dataset, or a .zip of them (unpacked, within the upload limit); each result file becomes a submission" }
                        } } } } },
                    "responses": {
                        "202": { "description": "queued: {submissions: [{id, submission, preflight, url}]}, and with one file also its fields at the top level" },
                        "401": { "description": "no valid API token (Authorization: Bearer TOKEN)" },
                        "200": { "description": "every file was already submitted for this method (same dataset and protocols): the existing submissions, not evaluated again, with the visibility asked for if one was given" },
                        "408": { "description": "the upload stalled: its body must keep delivering a minimum (by default 64 KiB every 20 s), however long the whole upload takes" },
                        "429": { "description": "over the fair-use limit of submissions per dataset: {error, retry_at}, and a Retry-After header" },
                        "400": { "description": "a missing or bad field" },
                        "413": { "description": "the file is larger than the limit" },
                        "422": { "description": "a file is not a valid result file, or is named for another dataset than the field says, or a zip holds other entries than result files, unpacks beyond the upload limit or holds too many entries; nothing is submitted: {error, problems: [{file, line, message}]}" },
                        "429": { "description": "over the fair-use limit for a dataset: nothing of the upload is submitted; {error, retry_at}" }
                    }
                }
            },
            "/api/v1/submissions/{id}": { "get": { "summary": "Status, progress, pre-flight report and, once done, the scores per protocol",
                "parameters": [id_param], "responses": { "200": { "description": "the submission" }, "404": { "description": "no such submission" } } } },
            "/api/v1/leaderboards/{protocol}": { "get": { "summary": "The leaderboard of a protocol",
                "parameters": [
                    { "name": "protocol", "in": "path", "required": true, "schema": { "type": "string", "enum": ["bop19", "eccv18"] } },
                    { "name": "dataset", "in": "query", "schema": { "type": "string" }, "description": "one dataset, with per-object scores" },
                    { "name": "sort", "in": "query", "schema": { "type": "string" }, "description": "average (default), time, method, or a dataset name" },
                    { "name": "training", "in": "query", "schema": { "type": "string", "enum": ["synthetic", "real", "both"] } },
                    { "name": "modality", "in": "query", "schema": { "type": "string", "enum": ["rgb", "depth", "rgb-d"] } }
                ],
                "responses": { "200": { "description": "{protocol, parameters, datasets, rows}" }, "404": { "description": "unknown protocol or dataset" } } } },
            "/api/v1/snapshots": { "get": { "summary": "Dated snapshots of the leaderboards, newest first",
                "responses": { "200": { "description": "{snapshots: [{id, taken_at (epoch ms), taken_by, url, boards: [{protocol, dataset (empty: all datasets), url, json_url}]}]}" } } } },
            "/api/v1/snapshots/{id}": { "get": { "summary": "One board of a snapshot: the bytes the leaderboard's JSON served when the snapshot was taken, unchanged since",
                "parameters": [
                    id_param,
                    { "name": "protocol", "in": "query", "schema": { "type": "string", "enum": ["bop19", "eccv18"] }, "description": "default: bop19" },
                    { "name": "dataset", "in": "query", "schema": { "type": "string" }, "description": "one dataset's board; default: all datasets" }
                ],
                "responses": { "200": { "description": "{protocol, parameters, datasets, rows} as /api/v1/leaderboards/{protocol} answered then" }, "404": { "description": "no such snapshot or board" } } } },
            "/api/v1/admin/snapshots": { "post": { "summary": "Take a snapshot of every board now (administrators; to anyone else this route does not exist)",
                "security": [{ "bearer": [] }],
                "responses": { "201": { "description": "{id, taken_at, taken_by, url, boards: [...]} as listed by /api/v1/snapshots" }, "404": { "description": "not an administrator" } } } },
            "/api/v1/openapi.json": { "get": { "summary": "This document", "responses": { "200": { "description": "OpenAPI 3.1" } } } }
        }
    })
}
