"""The book's toys: the five-state corridor, solved exactly, that the in-browser explorer plays step for step."""
