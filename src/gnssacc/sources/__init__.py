"""Input sources: each turns one kind of recording into a RecordedRun."""
