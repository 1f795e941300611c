# Sim worker: PyBullet Baxter, camera perception, simulated human; talks to the KB service over HTTP only.
# The core install and the `sim` extra.
# Build from the repository root:  docker build -f docker/worker.Dockerfile -t planhrc-worker .
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MPLBACKEND=Agg MPLCONFIGDIR=/tmp/matplotlib
# OpenMP, GL and GLib runtimes of PyBullet and OpenCV; not pinned, as in kb.Dockerfile.
# hadolint ignore=DL3008
RUN apt-get update && apt-get install -y --no-install-recommends libgomp1 libgl1 libglib2.0-0 \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /app
# 1. The dependencies alone (core + sim), pinned by constraints.txt; rebuilt only when they change.
COPY pyproject.toml constraints.txt docker/requirements.py ./
RUN python requirements.py sim > requirements.txt \
    && pip install --no-cache-dir -c constraints.txt -r requirements.txt
# 2. The project, a regular (non-editable) install.
COPY README.md LICENSE ./
COPY planhrc ./planhrc
COPY kb_service ./kb_service
COPY translator ./translator
COPY planner ./planner
COPY robot_sim ./robot_sim
COPY ontology ./ontology
COPY pipeline ./pipeline
COPY bench ./bench
COPY ros2 ./ros2
RUN pip install --no-cache-dir --no-deps -c constraints.txt . && rm -rf build
# 3. An unprivileged user that owns nothing but the output folder.
RUN groupadd --system --gid 10001 planhrc \
    && useradd --system --uid 10001 --gid 10001 --home-dir /out --shell /usr/sbin/nologin planhrc \
    && mkdir -p /out && chown planhrc:planhrc /out
USER 10001:10001
WORKDIR /out
VOLUME ["/out"]
# The demo against an external KB service: creates the object and goal, then runs the worker loop.
CMD ["planhrc", "demo", "--kb", "http://kb:8000", "--scenario", "fig13", "--out", "/out"]
