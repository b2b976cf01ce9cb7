"""Drawing and reports: the only part of terrapref that imports matplotlib."""
