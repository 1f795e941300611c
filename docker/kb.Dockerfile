# KB service: the ontology store, planners, VAL and the HTTP API, and `planhrc planning-worker`. The core install
# with the `postgresql` extra (psycopg, for replicas on one PostgreSQL: docker/replicas.yaml): no PyBullet, OpenCV or
# robot meshes (the `sim` extra), no JDK (the service runs no DL reasoner; `reasoner` extra).
# Build from the repository root:  docker build -f docker/kb.Dockerfile -t planhrc-kb .
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PLANHRC_DB=/data/planhrc.sqlite3
# libgomp1: OpenMP runtime of the planner binaries. Debian's point releases replace package versions, so the
# package is not pinned (the image's base tag pins the distribution).
# hadolint ignore=DL3008
RUN apt-get update && apt-get install -y --no-install-recommends libgomp1 && rm -rf /var/lib/apt/lists/*
WORKDIR /app
# 1. The dependencies alone, pinned by constraints.txt: this layer is rebuilt only when pyproject.toml or
#    constraints.txt change, not when the code does.
COPY pyproject.toml constraints.txt docker/requirements.py ./
RUN python requirements.py postgresql tracing > requirements.txt \
    && pip install --no-cache-dir -c constraints.txt -r requirements.txt
# 2. The project, a regular (non-editable) install: the TBox travels as package data of planhrc.ontology.
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
# 3. An unprivileged user that owns nothing but the store.
RUN groupadd --system --gid 10001 planhrc \
    && useradd --system --uid 10001 --gid 10001 --home-dir /data --shell /usr/sbin/nologin planhrc \
    && mkdir -p /data && chown planhrc:planhrc /data
USER 10001:10001
WORKDIR /data
VOLUME ["/data"]
EXPOSE 8000
# Readiness (/health/ready: the store's database answers, the TBox is loaded, planning is reachable): what
# `depends_on: condition: service_healthy` waits for. An orchestrator with two probes takes /health/live for the
# other (docs/operations.md).
HEALTHCHECK --interval=5s --timeout=3s --retries=12 \
  CMD ["python", "-c", "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/health/ready', timeout=2)"]
CMD ["planhrc", "serve", "--host", "0.0.0.0", "--port", "8000"]
