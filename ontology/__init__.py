"""The planHRC TBox (`planhrc.owl`), shipped as package data of `planhrc.ontology`, and the script that builds it."""
