# syntax=docker/dockerfile:1
# poseboard in a container: `docker build -t poseboard .`, or `docker compose up --build` with
# the docker-compose.yml next to this file. Two stages: the Rust toolchain builds the
# `poseboard` binary; a small Debian image runs it as an unprivileged user.

ARG RUST_VERSION=1

FROM rust:${RUST_VERSION}-bookworm AS builder
WORKDIR /src
COPY . .
# The registry and the target folder are cache mounts: a rebuild after a source change
# compiles only poseboard's own crates. The binary is copied out of the cache mount.
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release --locked -p server --bin poseboard \
    && install -m 0755 target/release/poseboard /usr/local/bin/poseboard

FROM debian:bookworm-slim AS runtime
# A fixed numeric id, so that orchestrators can check that it is not root (runAsNonRoot).
RUN groupadd --system --gid 10001 poseboard \
    && useradd --system --uid 10001 --gid poseboard --home-dir /var/lib/poseboard \
       --shell /usr/sbin/nologin poseboard \
    && mkdir -p /var/lib/poseboard /datasets \
    && chown poseboard:poseboard /var/lib/poseboard
COPY --from=builder /usr/local/bin/poseboard /usr/local/bin/poseboard
# Templates and migrations are built into the binary; the stylesheet and scripts are files.
COPY static /usr/share/poseboard/static
ENV POSEBOARD_STATIC=/usr/share/poseboard/static \
    POSEBOARD_DATA_DIR=/var/lib/poseboard \
    POSEBOARD_BIND=0.0.0.0:8080
USER 10001:10001
WORKDIR /var/lib/poseboard
EXPOSE 8080
ENTRYPOINT ["/usr/local/bin/poseboard"]
CMD ["serve"]
