"""The knowledge base: the planHRC ontology (TBox file + persistent ABox), reasoners and subsumption."""
