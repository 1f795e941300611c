# Sim worker: PyBullet Baxter, camera perception, simulated human; talks to the KB service over HTTP only.
# Build from the repository root:  docker build -f docker/worker.Dockerfile -t planhrc-worker .
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 MPLBACKEND=Agg
RUN apt-get update && apt-get install -y --no-install-recommends libgomp1 libgl1 libglib2.0-0 \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY pyproject.toml README.md ./
COPY planhrc ./planhrc
COPY kb_service ./kb_service
COPY translator ./translator
COPY planner ./planner
COPY robot_sim ./robot_sim
COPY ontology ./ontology
RUN pip install .
VOLUME ["/out"]
# The demo against an external KB service: creates the object and goal, then runs the worker loop.
CMD ["planhrc", "demo", "--kb", "http://kb:8000", "--scenario", "fig13", "--out", "/out"]
