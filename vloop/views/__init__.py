"""Pictures of a Mechanism and its Result: the offline HTML viewer, PNG plots, body geometry."""
