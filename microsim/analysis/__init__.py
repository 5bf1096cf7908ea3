"""Tables judged against models: ``compare`` (a model against a table, cell by cell or at points),
``fit`` (a model's parameters from a table), and their plots."""
