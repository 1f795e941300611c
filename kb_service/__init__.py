"""The planHRC knowledge-base service: HTTP API over the ontology and the cooperation model.

Build the app with `kb_service.app.create_app(settings)`; run it with `planhrc serve`.
"""
