"""Output writers: the atomic result folder, tables, summary and figures."""
